"""uavpipe: log-replay batch analytics for UAV flight data.

Import package ``pipeline`` of the ``uavpipe`` distribution. Subpackages follow the
one-way import order ``frames -> io -> preprocess -> models/align/estimate -> report``.
"""

__version__ = "0.3.0"
