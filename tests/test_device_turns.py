"""DeviceTurns (service/core/sim/device_turns.py): the loop's thread and the camera renderer take
turns launching on a shared device; a waiting renderer goes before the loop's next turn."""

from __future__ import annotations

import threading
import time

from service.core.sim.device_turns import DeviceTurns


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


def test_a_turn_lent_while_waiting_lets_the_render_launch_and_comes_back() -> None:
    turns, order = DeviceTurns(), []
    rendering, rendered = threading.Event(), threading.Event()

    def render() -> None:
        rendering.set()
        with turns.render_turn():
            order.append("render")
        rendered.set()

    with turns.loop_turn():
        thread = threading.Thread(target=render)
        thread.start()
        rendering.wait(5)
        with turns.lent():  # the loop waits for the device: the renderer launches meanwhile
            assert rendered.wait(5)
        order.append("loop, after the wait")
        lent_to_nobody = threading.Thread(target=lambda: turns.lent().__enter__())
        lent_to_nobody.start()  # another thread's `lent` gives nothing away
        lent_to_nobody.join(5)
        blocked = threading.Thread(target=render)
        rendered.clear()
        blocked.start()
        assert not rendered.wait(0.2)  # the turn is the loop's again
    thread.join(5)
    assert rendered.wait(5)
    blocked.join(5)
    assert order == ["render", "loop, after the wait", "render"]
