"""DeviceTurns (service/core/device_turns.py): the loop's thread and the camera renderer take
turns launching on a shared device; a waiting renderer goes before the loop's next turn."""

from __future__ import annotations

import threading
import time

from service.core.device_turns import DeviceTurns


def test_a_waiting_render_goes_before_the_loops_next_turn() -> None:
    turns, order = DeviceTurns(), []
    rendering = threading.Event()

    def render() -> None:
        rendering.set()
        with turns.render_turn():
            order.append("render")

    with turns.loop_turn():
        thread = threading.Thread(target=render)
        thread.start()
        rendering.wait(5)
        time.sleep(0.05)  # the renderer now waits for this turn to end
        assert order == []
    with turns.loop_turn():  # a loop that takes its turn again at once still lets it go first
        order.append("loop")
    thread.join(5)
    assert order == ["render", "loop"]


def test_the_loops_turn_goes_on_inside_itself() -> None:
    turns = DeviceTurns()
    with turns.loop_turn(), turns.loop_turn():  # a request served in a turn serves another
        pass
    with turns.render_turn():  # and the turn was given back
        pass
