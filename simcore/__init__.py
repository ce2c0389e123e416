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
