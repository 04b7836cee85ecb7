// roslib.js (npm `roslib`) against armfleet's rosbridge endpoint, for tests/test_rosbridge.py.
// Usage: node rosbridge_check.mjs ws://127.0.0.1:PORT/rosbridge WORLD_TOPIC_PREFIX
// Lists the topics, asks a topic's type, publishes a JointState command, waits until the
// subscribed state shows it, and prints one JSON line with what it saw.
import * as ROSLIB from "roslib";

const [url, prefix = ""] = process.argv.slice(2);
const fail = (why) => {
  console.log(JSON.stringify({ ok: false, error: String(why) }));
  process.exit(1);
};
setTimeout(() => fail("timed out"), 30000);

const ros = new ROSLIB.Ros({ url });
ros.on("error", (e) => fail(`connection error: ${e?.message ?? e}`));
const statuses = [];
ros.on("status", (s) => statuses.push(s));

ros.on("connection", () => {
  ros.getTopics((topics) => {
    ros.getTopicType(`${prefix}/joint_states`, (type) => {
      const states = new ROSLIB.Topic({
        ros,
        name: `${prefix}/joint_states`,
        messageType: "sensor_msgs/msg/JointState",
      });
      const commands = new ROSLIB.Topic({
        ros,
        name: `${prefix}/joint_commands`,
        messageType: "sensor_msgs/msg/JointState",
      });
      let sent = false;
      let frames = 0;
      states.subscribe((msg) => {
        frames += 1;
        if (!sent) {
          sent = true;
          commands.publish({ name: ["finger_joint"], position: [0.6] });
          return;
        }
        if (msg.position[6] > 0.5) {
          console.log(JSON.stringify({ ok: true, topics, type, frames, msg, statuses }));
          states.unsubscribe();
          ros.close();
          process.exit(0);
        }
      });
    }, fail);
  }, fail);
});
