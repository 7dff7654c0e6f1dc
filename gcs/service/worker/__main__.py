"""``python -m gcs.service.worker``: :func:`gcs.service.worker.main`.

The entry point is this package's ``__main__`` (not the module of the worker itself), so that
its planning jobs, each in a process forked from the worker's fork server, do not import the
worker again as their main module: :mod:`multiprocessing` leaves a main module named
``*.__main__`` alone, and the fork server has loaded what the jobs need.
"""

import sys

from gcs.service.worker import main

sys.exit(main())
