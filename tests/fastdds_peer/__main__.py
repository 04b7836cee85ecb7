"""`python -m tests.fastdds_peer`: build the Fast DDS peer (if needed) and print its path."""

import sys

from tests.fastdds_peer import PeerUnavailable, build

try:
    print(build(say=lambda m: print(m, file=sys.stderr)))
except PeerUnavailable as exc:
    print(exc, file=sys.stderr)
    raise SystemExit(1) from None
