"""The one exception type for bad input. The CLI prints it as one line and exits 2."""


class GridcostError(ValueError):
    """Bad input (missing file, unreadable mesh, NaN vertices, memory budget...). Message is one line."""
