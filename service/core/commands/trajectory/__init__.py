"""Trajectories: each world follows a JointTrajectory, sampled in the loop for all worlds at once.

The API every surface codes against (HTTP, WebSocket, ROS 2 actions, rosbridge):

- `spec.JointTrajectorySpec.build(robot_spec, joint_names, points, path_tolerance=(),
  goal_tolerance=(), goal_time_tolerance=0.0)` or `spec.parse(robot_spec, json_body)`: validate
  a trajectory_msgs/JointTrajectory (+ FollowJointTrajectory tolerances) completely; raises
  `BadCommand` (422) naming the field and the limit (`MAX_POINTS`, `MAX_DURATION_S`).
- `Control.start_trajectory(worlds, spec, source) -> list[Started]` (id, world, start_tick,
  end_tick): every world starts at the same tick, from its current target; a running trajectory
  on a world is preempted. Recorded in MCAP and replayed like every command.
- `Control.cancel_trajectory(worlds, source) -> list[TrajectoryStatus]`: stop and hold.
- `manager.TrajectoryManager` (`control.trajectories`, one per loop): `status(world)`,
  `get(id)`, `wait(id) -> Future[TrajectoryStatus]`, `add_listener(fn)` (called once per
  trajectory when it finishes: succeeded, or aborted with an `AbortReason`), `running()`
  (what a recording stores; `Control.resume_trajectory` puts one back in a replay).

Feedback (desired, actual, error per joint) is in `TrajectoryStatus`, as of the last snapshot.
A manual target command on one of a trajectory's joints and a reset stop it (reason
manual_override / reset) and the world holds where it was; commands on other joints (the
gripper's during an arm trajectory) leave it running. A fault aborts it (the world goes home).
"""

from service.core.commands.trajectory.spec import (
    MAX_DURATION_S,
    MAX_POINTS,
    JointTolerance,
    JointTrajectorySpec,
    TrajectoryPoint,
    parse,
)
from service.core.commands.trajectory.status import (
    AbortReason,
    Started,
    TrajectoryState,
    TrajectoryStatus,
)

__all__ = [
    "MAX_DURATION_S",
    "MAX_POINTS",
    "AbortReason",
    "JointTolerance",
    "JointTrajectorySpec",
    "Started",
    "TrajectoryPoint",
    "TrajectoryState",
    "TrajectoryStatus",
    "parse",
]
