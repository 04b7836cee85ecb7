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


class RedactTokens(logging.Filter):
    """Rewrites each record's message with `redact` (formatting its arguments first)."""

    def filter(self, record: logging.LogRecord) -> bool:
        try:
            message = record.getMessage()
        except Exception:  # a broken format: leave it to the handler to report
            return True
        clean = redact(message)
        if clean != message:
            record.msg, record.args = clean, None
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
