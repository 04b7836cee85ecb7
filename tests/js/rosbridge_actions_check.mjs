// roslib.js (npm `roslib`) Action against armfleet's rosbridge actions, for
// tests/test_rosbridge_actions.py.
// Usage: node rosbridge_actions_check.mjs ws://127.0.0.1:PORT/rosbridge ACTION
// Sends a 0.6 s FollowJointTrajectory goal (feedback, result), a bad goal (failed callback),
// a 20 s goal that it cancels (failed callback with the CANCELED status), another that
// cancelAllGoals stops, and prints one JSON line with what it saw.
import * as ROSLIB from "roslib";

const [url, name] = process.argv.slice(2);
const fail = (why) => {
  console.log(JSON.stringify({ ok: false, error: String(why) }));
  process.exit(1);
};
setTimeout(() => fail("timed out"), 45000);

const arm = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint",
  "wrist_2_joint", "wrist_3_joint"];
const goal = (positions, sec) => ({
  trajectory: {
    joint_names: arm,
    points: [{ positions, time_from_start: { sec: Math.floor(sec), nanosec: Math.round((sec % 1) * 1e9) } }],
  },
});
const ros = new ROSLIB.Ros({ url });
ros.on("error", (e) => fail(`connection error: ${e?.message ?? e}`));
const action = new ROSLIB.Action({ ros, name, actionType: "control_msgs/action/FollowJointTrajectory" });
const seen = { feedback: 0 };

ros.on("connection", () => {
  action.sendGoal(
    goal([0.2, -1.4, 1.5, -1.7, -1.5, 0.1], 0.6),
    (result) => {
      seen.result = result;
      action.sendGoal(goal([0.2, -1.4, 1.5, -1.7, -1.5], 1.0), () => fail("bad goal succeeded"),
        undefined, (error) => {
          seen.bad = error;
          const id = action.sendGoal(goal([1.0, -1.0, 1.0, -1.0, -1.0, 1.0], 20.0),
            () => fail("cancelled goal succeeded"), (fb) => {
              if (!seen.cancelSent) {
                seen.cancelSent = true;
                action.cancelGoal(id);
              }
            }, (error) => {
              seen.cancelled = error;
              // cancelAllGoals: call_service <action>/_action/cancel_goal with empty args
              action.sendGoal(goal([-1.0, -1.0, 1.0, -1.0, -1.0, -1.0], 20.0),
                () => fail("goal succeeded despite cancelAllGoals"), () => {
                  if (!seen.cancelAllSent) {
                    seen.cancelAllSent = true;
                    action.cancelAllGoals();
                  }
                }, (error) => {
                  seen.cancelledAll = error;
                  console.log(JSON.stringify({ ok: true, ...seen }));
                  ros.close();
                  process.exit(0);
                });
            });
        });
    },
    (feedback) => {
      seen.feedback += 1;
      seen.lastFeedback = feedback;
    },
    (error) => fail(`goal failed: ${error}`),
  );
});
