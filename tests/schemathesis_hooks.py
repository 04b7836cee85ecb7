"""Schemathesis hooks for tests/test_contract.py's fuzz run (loaded through SCHEMATHESIS_HOOKS).

The fuzzer sends `POST /v1/sim/mode {"mode": "fast"}` among its cases, and the server then steps
its 16 worlds as fast as the machine allows until a later case happens to choose another mode:
for about a minute of the run (measured: 7 s to 74 s of a 190 s run), on every core the server
gets. That minute is spent on the rest of the suite's CPU and slows the fuzz's own requests
(a camera picture request behind it ran past schemathesis' request timeout on a loaded box).
How time advances is not part of the HTTP contract: the replies are the same in every mode
(`/v1/sim/step` refuses unless paused, and fast is not paused). So once the server accepted
fast, this puts it back to realtime; every case is still sent and checked as before, and this
request of ours is not one of them. Each time it does, it adds a line to UNDONE in the run's
folder (the test checks that the hook ran).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import requests
import schemathesis

MODE_PATH = "/v1/sim/mode"
UNDONE = "fast_mode_undone.txt"  # in the working folder schemathesis runs in


@schemathesis.hook
def after_call(context: Any, case: Any, response: Any) -> None:
    """After an accepted `fast`, set `realtime` again with the same credentials."""
    body = case.body if isinstance(case.body, dict) else {}
    if case.path != MODE_PATH or response.status_code != 200 or body.get("mode") != "fast":
        return
    sent = response.request
    auth = {k: v for k, v in sent.headers.items() if k.lower() == "authorization"}
    back = requests.post(sent.url, json={"mode": "realtime"}, headers=auth, timeout=60)
    back.raise_for_status()
    with Path(UNDONE).open("a") as f:
        f.write(f"{case.path} fast -> realtime: {back.status_code}\n")
