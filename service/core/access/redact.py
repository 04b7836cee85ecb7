"""Tokens never reach a log: a logging filter that blanks them wherever a line would carry one.

A browser socket presents its token in the URL (`?token=`), the page is opened with `?lease=`,
and uvicorn's access and connection lines print the whole path; so every record of the loggers
given to `install` has such query values, and anything shaped like a lease token, replaced by
`<redacted>` before it is written. (armfleet's own code never logs a token in the first place.)
"""

from __future__ import annotations

import logging
import re

_QUERY = re.compile(r"((?:^|[?&;\s])(?:token|lease)=)[^&\s\"']+", re.IGNORECASE)
_LEASE = re.compile(r"\b(lease_[0-9a-f]+_)[A-Za-z0-9_-]+")
_SUBPROTOCOL = re.compile(r"(armfleet\.token\.)[^\s,\"']+")
REDACTED = "<redacted>"


def redact(text: str) -> str:
    """`text` with every token it might hold blanked."""
    text = _QUERY.sub(rf"\1{REDACTED}", text)
    text = _SUBPROTOCOL.sub(rf"\1{REDACTED}", text)
    return _LEASE.sub(rf"\1{REDACTED}", text)


def _clean(value: object) -> object:
    return redact(value) if isinstance(value, str) else value


class RedactTokens(logging.Filter):
    """Blanks tokens in each record: in its format string and in each of its arguments, which
    keep their shape. Why not the formatted line alone: a formatter may read the arguments
    themselves (uvicorn's access formatter unpacks (client, method, path, version, status)), so
    a record whose arguments were dropped breaks it. Only where a token survives that (inside
    an argument that is not a string) is the record collapsed to its redacted line."""

    def filter(self, record: logging.LogRecord) -> bool:
        try:
            message = record.getMessage()
        except Exception:  # a broken format: leave it to the handler to report
            return True
        if redact(message) == message:
            return True
        if isinstance(record.msg, str):
            record.msg = redact(record.msg)
        if isinstance(record.args, tuple):
            record.args = tuple(_clean(a) for a in record.args)
        elif isinstance(record.args, dict):
            record.args = {k: _clean(v) for k, v in record.args.items()}
        try:
            again = record.getMessage()
        except Exception:
            again = None
        if again is None or redact(again) != again:
            record.msg, record.args = redact(message), ()
        return True


def install(*names: str) -> None:
    """Add the filter to these loggers (and their handlers, which see propagated records)."""
    f = RedactTokens()
    for name in names:
        logger = logging.getLogger(name)
        if not any(isinstance(x, RedactTokens) for x in logger.filters):
            logger.addFilter(f)
        for handler in logger.handlers:
            if not any(isinstance(x, RedactTokens) for x in handler.filters):
                handler.addFilter(f)
