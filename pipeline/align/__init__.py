"""align subpackage."""


#: the stage's entry points, importable from the package; loaded on first use so importing the
#: package stays light
_ENTRY_POINTS = {'run_align': 'run'}


def __getattr__(name: str):
    if name in _ENTRY_POINTS:
        import importlib

        return getattr(importlib.import_module(f"{__name__}.{_ENTRY_POINTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
