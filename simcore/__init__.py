"""CARLOS' simulation core and command line (the distribution `carlos-sim`; the command is `carlos`)."""

#: the name this project has on PyPI (`pip install carlos-sim`); `carlos` there is another project
DISTRIBUTION = "carlos-sim"


def version() -> str:
    """The installed version of carlos-sim ("unknown" when it is not installed, e.g. run from a copy of the
    sources on sys.path)."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as installed

    try:
        return installed(DISTRIBUTION)
    except PackageNotFoundError:
        return "unknown"


def compiled() -> bool:
    """Whether the step loop's modules run as machine code (a wheel built with mypyc: setup.py's COMPILED)
    rather than as Python source (an editable install, a pure-Python wheel)."""
    from importlib.machinery import EXTENSION_SUFFIXES
    from importlib.util import find_spec

    spec = find_spec("simcore.scenario.engine")
    return spec is not None and (spec.origin or "").endswith(tuple(EXTENSION_SUFFIXES))
