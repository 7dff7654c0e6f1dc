"""Errors raised by gcs: one base class, subclassing built-ins where one fits."""

from __future__ import annotations


class GcsError(Exception):
    """Base of every error gcs raises on purpose."""


class ConnectionStringError(GcsError, ValueError):
    """A connection string gcs cannot parse."""


class LinkTimeout(GcsError, TimeoutError):
    """A link did not connect, or a vehicle did not appear, in time."""


class LinkClosed(GcsError, ConnectionError):
    """The link was closed while an operation was waiting on it."""
