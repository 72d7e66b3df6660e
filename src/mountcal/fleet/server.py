"""Imported first by the fleet's worker server (the ``forkserver``), and by nothing else.

It makes the server ignore Ctrl-C while it imports mountcal for the workers: an interrupt there
would print the import's traceback from a process the user never started. (The server ends by
itself when the command does: its pipe to the command closes.) The workers forked from it inherit
the setting — a Ctrl-C is the command's to handle — and watch the command themselves
(:func:`mountcal.fleet.engines.worker_started`).
"""

from __future__ import annotations

import signal

signal.signal(signal.SIGINT, signal.SIG_IGN)
