"""Shared test helpers (importable as ``helpers``; fixtures in conftest.py): seeded rng (PIPELINE_TEST_SEED, printed), the real-data folder, tmp logs.

Real-data tests use the ``realdata`` fixture: it skips with a clear reason when
``../shared/realdata`` is absent, and fails instead when ``UAVPIPE_REQUIRE_SHARED=1`` (CI).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
REALDATA = Path(os.environ.get("UAVPIPE_REALDATA", ROOT.parent / "shared" / "realdata"))
REQUIRE_SHARED = os.environ.get("UAVPIPE_REQUIRE_SHARED") == "1"
TEST_SEED = int(os.environ.get("PIPELINE_TEST_SEED", "20261123"))


def need_shared(reason: str = "") -> None:
    """Skip (or fail under UAVPIPE_REQUIRE_SHARED=1) when ../shared/realdata is absent."""
    if not REALDATA.is_dir():
        msg = f"../shared/realdata not found at {REALDATA}{': ' + reason if reason else ''}"
        if REQUIRE_SHARED:
            pytest.fail(f"UAVPIPE_REQUIRE_SHARED=1 but {msg}")
        pytest.skip(msg)


def realdata_file(rel: str) -> Path:
    """Path of one real log under ../shared/realdata, skipping/failing per :func:`need_shared`."""
    need_shared(rel)
    p = REALDATA / rel
    if not p.exists():
        if REQUIRE_SHARED:
            pytest.fail(f"missing real log {p}")
        pytest.skip(f"missing real log {p}")
    return p


def pymavlink_messages(path) -> list:
    """Every message of a tlog through the documented pymavlink loop (the test oracle):
    ``mavutil.mavlink_connection`` + ``recv_msg``, restoring the global dialect state that
    mavutil mutates (``MAVLINK20`` and the module-level ``mavlink``)."""
    from pymavlink import mavutil

    saved = (os.environ.get("MAVLINK20"), mavutil.mavlink, mavutil.current_dialect)
    try:
        conn = mavutil.mavlink_connection(str(path), robust_parsing=True)
        out = []
        while (msg := conn.recv_msg()) is not None:
            out.append(msg)
        conn.close()
        return out
    finally:
        if saved[0] is None:
            os.environ.pop("MAVLINK20", None)
        else:
            os.environ["MAVLINK20"] = saved[0]
        mavutil.mavlink, mavutil.current_dialect = saved[1], saved[2]


def pymavlink_by_type(path) -> dict[str, list]:
    """Every message of a log (DataFlash or tlog) through the pymavlink loop, grouped by type."""
    out: dict[str, list] = {}
    for msg in pymavlink_messages(path):
        out.setdefault(msg.get_type(), []).append(msg)
    return out
