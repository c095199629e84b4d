// A Foxglove WebSocket client (npm @foxglove/ws-protocol, subprotocol foxglove.sdk.v1) for the tests:
// subscribes to the given topics, decodes every message as Foxglove does (ros2msg schemas + CDR with
// @foxglove/rosmsg2-serialization, protobuf schemas with protobufjs, JSON) for SECONDS, records the server's
// time broadcasts, and prints one JSON report on stdout.
//   node client.js ws://127.0.0.1:8765 /particle/pose,/foxglove/scene 5    (TOPICS "*": all advertised)
"use strict";
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const { parse: parseRosMsg } = require("@foxglove/rosmsg");
const { MessageReader } = require("@foxglove/rosmsg2-serialization");
const protobuf = require("protobufjs");
const descriptor = require("protobufjs/ext/descriptor");
const WebSocket = require("ws");

const [url, topicList, secondsText] = process.argv.slice(2);
const everything = topicList === "*"; // "*": every topic the server advertises
const wanted = new Set(everything ? [] : topicList.split(","));
const seconds = Number(secondsText);
const report = { topics: {}, times: [], advertised: [], errors: [] };
const decoders = new Map(); // channel id -> { topic, decode }
const subscriptions = new Map(); // subscription id -> channel id

function decoderFor(channel) {
  if (channel.encoding === "cdr" && channel.schemaEncoding === "ros2msg") {
    const reader = new MessageReader(parseRosMsg(channel.schema, { ros2: true }));
    return (data) => reader.readMessage(data);
  }
  if (channel.encoding === "protobuf") {
    const set = descriptor.FileDescriptorSet.decode(Buffer.from(channel.schema, "base64"));
    const type = protobuf.Root.fromDescriptor(set).lookupType(channel.schemaName);
    return (data) => type.toObject(type.decode(data), { longs: Number, defaults: true });
  }
  if (channel.encoding === "json") {
    const text = new TextDecoder();
    return (data) => JSON.parse(text.decode(data));
  }
  throw new Error(`${channel.topic}: no decoder for ${channel.encoding}/${channel.schemaEncoding}`);
}

function summarize(topic, msg) {
  if (msg.header && msg.poses) {
    return { frame_id: msg.header.frame_id, xs: msg.poses.map((p) => p.position.x),
             zs: msg.poses.map((p) => p.position.z) };
  }
  if (msg.header && msg.pose) {
    return { frame_id: msg.header.frame_id, stamp: msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9,
             x: msg.pose.position.x, z: msg.pose.position.z };
  }
  if (msg.entities) {
    const byId = Object.fromEntries(msg.entities.map((e) => [e.id, e]));
    const sphere = byId.part?.spheres[0];
    return { entities: msg.entities.map((e) => e.id), frames: msg.entities.map((e) => e.frame_id),
             stamp: byId.part ? byId.part.timestamp.seconds + byId.part.timestamp.nanos * 1e-9 : null,
             surface_points: (byId.surface?.lines[0]?.points ?? []).length,
             actuators: (byId.actuators?.cubes ?? []).length,
             part: sphere ? { x: sphere.pose.position.x, z: sphere.pose.position.z, diameter: sphere.size.x,
                              color: [sphere.color.r, sphere.color.g, sphere.color.b],
                              label: byId.part.texts[0]?.text } : null,
             other_parts: (byId.other_parts?.spheres ?? []).map((o) => ({ x: o.pose.position.x, z: o.pose.position.z })) };
  }
  if ("q_max" in msg) {
    return { friction: msg.friction, q_max: msg.q_max, normal_load: msg.normal_load };
  }
  return {};
}

const client = new FoxgloveClient({ ws: new WebSocket(url, ["foxglove.sdk.v1"]) });
let started = false;
client.on("error", (err) => report.errors.push(String(err && err.message ? err.message : err)));
client.on("serverInfo", (info) => { report.server = { name: info.name, capabilities: info.capabilities }; });
client.on("advertise", (channels) => {
  for (const channel of channels) {
    report.advertised.push(channel.topic);
    if (!everything && !wanted.has(channel.topic)) continue;
    try {
      decoders.set(channel.id, { topic: channel.topic, decode: decoderFor(channel) });
    } catch (err) {
      report.errors.push(String(err.message));
      continue;
    }
    report.topics[channel.topic] = { received: 0, decoded: 0, schema: channel.schemaName };
    subscriptions.set(client.subscribe(channel.id), channel.id);
  }
  if (!started && (everything ? subscriptions.size > 0 : subscriptions.size === wanted.size)) {
    started = true;
    setTimeout(finish, seconds * 1000);
  }
});
client.on("message", ({ subscriptionId, data }) => {
  const entry = decoders.get(subscriptions.get(subscriptionId));
  if (!entry) return;
  const stats = report.topics[entry.topic];
  stats.received += 1;
  try {
    stats.last = summarize(entry.topic, entry.decode(new Uint8Array(data.buffer, data.byteOffset, data.byteLength)));
    stats.decoded += 1;
  } catch (err) {
    if (stats.decoded === 0) report.errors.push(`${entry.topic}: ${err.message}`);
  }
});
client.on("time", ({ timestamp }) => report.times.push(Number(timestamp) * 1e-9));

function finish() {
  for (const id of subscriptions.keys()) client.unsubscribe(id);
  setTimeout(() => {
    client.close();
    const t = report.times;
    report.time_count = t.length;
    report.time_first = t.length ? t[0] : null;
    report.time_last = t.length ? t[t.length - 1] : null;
    report.time_monotonic = t.every((v, i) => i === 0 || v >= t[i - 1]);
    delete report.times;
    process.stdout.write(JSON.stringify(report) + "\n");
    process.exit(0);
  }, 500);
}
setTimeout(() => { report.errors.push("no connection within 30 s"); finish(); }, 30000).unref();
