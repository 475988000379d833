"""``python -m radiosity`` runs the command line."""

from .cli import entry

entry()
