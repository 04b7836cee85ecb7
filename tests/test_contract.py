"""The OpenAPI contract under fuzzing: schemathesis (all checks, fixed seed) finds nothing.

Every status a route can answer is documented, every rule the server enforces is stated in the
schema (joint names, increment's two shapes as oneOf, equal lengths, strict integers, the
`worlds=` pattern), so schema-valid requests are accepted and schema-invalid ones refused.
A real server over real sockets; schemathesis is the judge.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import httpx
import pytest

# Bounded so that the run stays well under a minute on the 2-core CI machine.
MAX_EXAMPLES = 20
SEED = 20261122


def test_schemathesis_finds_nothing(server, tmp_path):
    cmd = [
        sys.executable,
        "-m",
        "schemathesis.cli",
        "--config-file",
        str(Path(__file__).with_name("schemathesis.toml")),
        "run",
        f"{server.url}/openapi.json",
        "--checks",
        "all",
        "--seed",
        str(SEED),
        "--max-examples",
        str(MAX_EXAMPLES),
        "--workers",
        "1",
        "--no-shrink",
        "--request-timeout",
        "10",
        "--report",
        "junit",
        "--report-dir",
        str(tmp_path),
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, cwd=tmp_path)
    summary = [line for line in proc.stdout.splitlines() if "generated" in line]
    assert proc.returncode == 0, proc.stdout[-6000:] + proc.stderr[-2000:]
    assert summary and "passed" in summary[-1], proc.stdout[-2000:]
    print(summary[-1].strip())  # e.g. "700 generated, 700 passed" (pytest -s shows it)


@pytest.mark.parametrize(
    ("body", "status"),
    [
        ({"worlds": [False]}, 422),  # a boolean is not a world id (was: reset world 0)
        ({"worlds": [1.0]}, 200),  # JSON has one number type: 1.0 is the integer 1
        ({"worlds": [1.5]}, 422),
        ({"worlds": ["1"]}, 422),
    ],
)
def test_world_ids_are_strict_integers(server, body, status):
    r = httpx.post(f"{server.url}/v1/reset", json=body, timeout=10)
    assert r.status_code == status, r.text


def test_the_schema_states_the_cross_field_rules(server):
    spec = httpx.get(f"{server.url}/openapi.json", timeout=10).json()
    schemas = spec["components"]["schemas"]
    shapes = schemas["IncrementRequest"]["oneOf"]
    assert [sorted(s["required"]) for s in shapes] == [["delta", "joint"], ["deltas"]]
    lengths = schemas["JointTargets"]["oneOf"]
    named, nameless = lengths[:-1], lengths[-1]
    assert [b["properties"]["name"]["minItems"] for b in named] == list(range(1, 8))
    assert all(b["required"] == ["name"] for b in named)
    # no names: every joint's position, in joint order (the seed's Isaac subscriber's reading)
    assert nameless["properties"]["name"] == {"maxItems": 0}
    assert nameless["properties"]["position"] == {"minItems": 7, "maxItems": 7}
    state = spec["paths"]["/v1/worlds/state"]["get"]
    assert state["parameters"][0]["schema"]["anyOf"][0]["pattern"].startswith("^[0-9]+")
    increment = spec["paths"]["/v1/worlds/{world}/increments"]["post"]["responses"]
    assert {"400", "404", "413", "422", "503"} <= set(increment)
