"""Loads the timeline probe (tlpatch.py) into a server started with TL_OUT=path (`-m`): at the
start of the main module, once sys.path holds the tree (not during site's own start)."""

import os

if os.environ.get("TL_OUT"):
    import runpy

    _run = runpy._run_module_as_main

    def _run_with_probe(*args, **kwargs):
        import tlpatch

        tlpatch.install(os.environ["TL_OUT"])
        return _run(*args, **kwargs)

    runpy._run_module_as_main = _run_with_probe
