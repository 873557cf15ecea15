"""What a study is, how its cases are drawn and fanned out, and how its results are stored.

Imports :mod:`isolab.engine`; nothing here imports the web service.
"""

from isolab.engine import __version__

__all__ = ["__version__"]
