// The outside client of tests/tests/foxglove.rs: Foxglove's own protocol
// library (@foxglove/ws-protocol, on the npm package `ws`) against
// `nerve foxglove`. Each scenario prints JSON lines on stdout for the Rust
// test to check, and exits 0 when it ran to its end (what it saw is for the
// test to judge), 1 when it could not. Every wait is bounded.
//
//   node client.js watch URL SUBPROTOCOL TOPIC COUNT
//   node client.js refused URL SUBPROTOCOL [ORIGIN]
//   node client.js stall URL TOPIC PAUSE_MS
//   node client.js params URL NAME GOOD BAD
//   node client.js graph URL TOPIC [SERVICE]
//   node client.js publish URL TOPIC JSON COUNT
//   node client.js cycles URL TOPIC N
//   node client.js drive URL PUB_TOPIC JSON SUB_TOPIC
//   node client.js teleop URL PUB_TOPIC LINEAR ANGULAR SECONDS SUB_TOPIC
//   node client.js idle URL MS
//   node client.js services URL
//   node client.js call URL SERVICE JSON...   (each JSON a request, sent at once, in order)
//   node client.js all URL MS          (nerve-bench foxglove: every channel, read until killed or MS)
//   node client.js camera URL NOTICE_TOPIC MS   (nerve-bench foxglove: NOTICE_TOPIC and its /image)
"use strict";

const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");

const LIMIT_MS = 20000;
const say = (obj) => process.stdout.write(JSON.stringify(obj) + "\n");
const fail = (why) => {
  say({ error: String(why) });
  process.exit(1);
};
let limit = setTimeout(() => fail(`not done within ${LIMIT_MS} ms`), LIMIT_MS).unref();
// A scenario that runs `ms` on purpose is bounded by that plus the usual limit.
const limitTo = (ms) => {
  clearTimeout(limit);
  limit = setTimeout(() => fail(`not done within ${ms + LIMIT_MS} ms`), ms + LIMIT_MS).unref();
};

function connect(url, subprotocol) {
  const ws = new WebSocket(url, [subprotocol || FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
  const client = new FoxgloveClient({ ws });
  const state = { ws, client, channels: new Map(), serverInfo: null, statuses: [] };
  client.on("serverInfo", (info) => (state.serverInfo = info));
  client.on("advertise", (chs) => chs.forEach((c) => state.channels.set(c.topic, c)));
  client.on("unadvertise", (ids) => {
    for (const [t, c] of state.channels) if (ids.includes(c.id)) state.channels.delete(t);
  });
  client.on("status", (s) => state.statuses.push(s));
  state.services = new Map();
  client.on("advertiseServices", (list) => list.forEach((v) => state.services.set(v.name, v)));
  client.on("unadvertiseServices", (ids) => {
    for (const [n, v] of state.services) if (ids.includes(v.id)) state.services.delete(n);
  });
  client.on("error", (e) => fail(`client error: ${e && e.message}`));
  return state;
}

// Resolves when `check()` holds, polling every 20 ms, or fails after `ms`.
function until(check, ms, what) {
  return new Promise((resolve) => {
    const t0 = Date.now();
    const tick = () => {
      const v = check();
      if (v) return resolve(v);
      if (Date.now() - t0 > ms) return fail(`timed out waiting for ${what}`);
      setTimeout(tick, 20);
    };
    tick();
  });
}

const decode = (data) => JSON.parse(Buffer.from(data.buffer, data.byteOffset, data.byteLength).toString("utf8"));

async function watch(url, subprotocol, topic, count) {
  const s = connect(url, subprotocol);
  const ch = await until(() => s.serverInfo && s.channels.get(topic), 10000, `channel ${topic}`);
  say({
    subprotocol: s.ws.protocol,
    serverInfo: s.serverInfo,
    topics: [...s.channels.keys()].sort(),
    channel: ch,
  });
  const samples = [];
  const sub = s.client.subscribe(ch.id);
  s.client.on("message", (m) => {
    if (m.subscriptionId === sub) samples.push({ timestamp: m.timestamp.toString(), data: decode(m.data) });
  });
  await until(() => samples.length >= count, 10000, `${count} samples`);
  s.client.unsubscribe(sub);
  say({ samples: samples.slice(0, count) });
  s.client.close();
}

function refused(url, subprotocol, origin) {
  const ws = new WebSocket(url, [subprotocol], origin ? { origin } : {});
  ws.on("open", () => fail(`the server accepted subprotocol ${subprotocol}`));
  ws.on("unexpected-response", (req, res) => {
    let body = "";
    res.on("data", (d) => (body += d));
    res.on("end", () => {
      say({ refused: true, status: res.statusCode, body });
      process.exit(0);
    });
  });
  ws.on("error", (e) => {
    say({ refused: true, error: e.message });
    process.exit(0);
  });
}

// Subscribes to `topic`, then stops reading its socket for `pause` ms
// (the server's buffers fill, pings go unanswered), then reads again and
// tells whether the server had closed the connection.
async function stall(url, topic, pause) {
  const s = connect(url);
  const ch = await until(() => s.channels.get(topic), 10000, `channel ${topic}`);
  let received = 0;
  let closed = false;
  s.client.on("message", () => received++);
  s.client.on("close", () => (closed = true));
  s.client.subscribe(ch.id);
  await until(() => received > 0, 10000, "a first sample");
  s.ws._socket.pause();
  say({ paused: true, received });
  await new Promise((r) => setTimeout(r, pause));
  s.ws._socket.resume();
  await until(() => closed, 10000, "the server to close the stalled connection");
  say({ closed, received });
  process.exit(0);
}

async function params(url, name, good, bad) {
  const s = connect(url);
  await until(() => s.serverInfo, 10000, "serverInfo");
  const values = [];
  s.client.on("parameterValues", (v) => values.push(v));
  s.client.getParameters([], "all");
  const all = await until(() => values.find((v) => v.id === "all"), 10000, "all parameters");
  const before = all.parameters.find((p) => p.name === name);
  s.client.subscribeParameterUpdates([name]);
  let n = s.statuses.length;
  s.client.setParameters([{ name, value: Number(good) }], "set");
  // answered with the new value, or refused (no token) with a status
  await until(() => values.find((v) => v.id === "set") || s.statuses.length > n, 10000, "the set's answer");
  const set = values.find((v) => v.id === "set") || null;
  const setRefusal = set ? null : s.statuses[s.statuses.length - 1];
  n = s.statuses.length;
  s.client.setParameters([{ name, value: Number(bad) }], "bad");
  const refusal = await until(() => s.statuses.length > n && s.statuses[s.statuses.length - 1], 10000, "a refusal");
  // a set that was taken is told to the subscriber of updates
  const update = set
    ? await until(() => values.find((v) => v.id === undefined && v.parameters.some((p) => p.name === name)), 10000, "an update")
    : null;
  s.client.getParameters([name], "after");
  const after = await until(() => values.find((v) => v.id === "after"), 10000, "the value after");
  say({ serverInfo: s.serverInfo, count: all.parameters.length, before, set: set && set.parameters, setRefusal, refusal, update, after: after.parameters });
  s.client.close();
}

// Prints the first connection graph, then the first one that shows `topic`
// feeding an agent it did not feed before; with `service`, then the first
// one that advertises it and the first after that which names it removed.
async function graph(url, topic, service) {
  const s = connect(url);
  await until(() => s.serverInfo, 10000, "serverInfo");
  const updates = [];
  s.client.on("connectionGraphUpdate", (u) => updates.push(u));
  s.client.subscribeConnectionGraph();
  const first = await until(() => updates[0], 10000, "a connection graph");
  const subs = (u) => (u.subscribedTopics.find((t) => t.name === topic) || { subscriberIds: [] }).subscriberIds;
  const before = subs(first);
  say({ first, capabilities: s.serverInfo.capabilities });
  const changed = await until(
    () => updates.find((u) => subs(u).some((id) => !before.includes(id))),
    15000,
    `a new subscriber of ${topic}`,
  );
  say({ changed });
  if (service) {
    const served = await until(
      () => updates.find((u) => (u.advertisedServices || []).some((v) => v.name === service)),
      15000,
      `${service} in advertisedServices`,
    );
    say({ served });
    const after = updates.indexOf(served);
    const removed = await until(
      () => updates.slice(after).find((u) => (u.removedServices || []).includes(service)),
      15000,
      `${service} in removedServices`,
    );
    say({ removed });
  }
  s.client.close();
}

async function publish(url, topic, json, count) {
  const s = connect(url);
  await until(() => s.serverInfo, 10000, "serverInfo");
  const id = s.client.advertise({ topic, encoding: "json", schemaName: "nerve::Tick" });
  const bytes = new TextEncoder().encode(json);
  say({ capabilities: s.serverInfo.capabilities, advertised: id });
  for (let i = 0; i < count; i++) {
    s.client.sendMessage(id, bytes);
    await new Promise((r) => setTimeout(r, 50));
  }
  // a message of the wrong shape, refused with a status
  const n = s.statuses.length;
  s.client.sendMessage(id, new TextEncoder().encode('{"nope": 1}'));
  const refusal = await until(() => s.statuses.length > n && s.statuses[s.statuses.length - 1], 10000, "a refusal");
  say({ sent: count, refusal, statuses: s.statuses });
  s.client.close();
}

// Subscribes and unsubscribes `n` times, each time waiting for a sample.
async function cycles(url, topic, n) {
  const s = connect(url);
  const ch = await until(() => s.channels.get(topic), 10000, `channel ${topic}`);
  let current = -1;
  let got = 0;
  s.client.on("message", (m) => {
    if (m.subscriptionId === current) got++;
  });
  for (let i = 0; i < n; i++) {
    got = 0;
    current = s.client.subscribe(ch.id);
    await until(() => got > 0, 10000, `a sample in cycle ${i}`);
    s.client.unsubscribe(current);
  }
  say({ cycles: n });
  s.client.close();
}

// Subscribes to `subTopic`, publishes `json` into `pubTopic` every 50 ms
// until a message arrives on `subTopic`; prints that channel and message.
async function drive(url, pubTopic, json, subTopic) {
  const s = connect(url);
  const ch = await until(() => s.channels.get(subTopic), 10000, `channel ${subTopic}`);
  let got = null;
  const sub = s.client.subscribe(ch.id);
  s.client.on("message", (m) => {
    if (m.subscriptionId === sub && !got) got = { timestamp: m.timestamp.toString(), data: decode(m.data) };
  });
  const id = s.client.advertise({ topic: pubTopic, encoding: "json", schemaName: "" });
  const bytes = new TextEncoder().encode(json);
  const timer = setInterval(() => s.client.sendMessage(id, bytes), 50);
  await until(() => got, 10000, `a message on ${subTopic}`);
  clearInterval(timer);
  say({ channel: ch, message: got, statuses: s.statuses });
  s.client.close();
}

// As Foxglove's Teleop panel does: advertises `pubTopic` as a
// geometry_msgs/Twist in JSON and publishes a Twist of `linear` m/s and
// `angular` rad/s every 100 ms for `seconds`, then stops (the panel
// released); meanwhile subscribed to `subTopic`, prints the first and last
// message seen there, and the statuses the server sent.
async function teleop(url, pubTopic, linear, angular, seconds, subTopic) {
  const s = connect(url);
  const ch = await until(() => s.serverInfo && s.channels.get(subTopic), 10000, `channel ${subTopic}`);
  if (!s.serverInfo.capabilities.includes("clientPublish")) fail(`no clientPublish: ${s.serverInfo.capabilities}`);
  const seen = [];
  const sub = s.client.subscribe(ch.id);
  s.client.on("message", (m) => {
    if (m.subscriptionId === sub) seen.push(decode(m.data));
  });
  await until(() => seen.length > 0, 10000, `a first message on ${subTopic}`);
  const first = seen[seen.length - 1];
  const id = s.client.advertise({ topic: pubTopic, encoding: "json", schemaName: "geometry_msgs/Twist" });
  const twist = { linear: { x: linear, y: 0, z: 0 }, angular: { x: 0, y: 0, z: angular } };
  const bytes = new TextEncoder().encode(JSON.stringify(twist));
  let sent = 0;
  const t0 = Date.now();
  while (Date.now() - t0 < seconds * 1000) {
    s.client.sendMessage(id, bytes);
    sent++;
    await new Promise((r) => setTimeout(r, 100));
  }
  s.client.unadvertise(id);
  const n = seen.length;
  await until(() => seen.length > n, 10000, `a message on ${subTopic} after the last Twist`);
  say({ sent, first, last: seen[seen.length - 1], count: seen.length, statuses: s.statuses });
  s.client.close();
}

// Connects, subscribes to nothing, says so, and stays connected for `ms`.
async function idle(url, ms) {
  const s = connect(url);
  await until(() => s.serverInfo, 10000, "serverInfo");
  say({ connected: true, channels: s.channels.size });
  await new Promise((r) => setTimeout(r, ms));
  say({ done: true, statuses: s.statuses });
  s.client.close();
}

// Subscribes to every channel advertised (and to those advertised later)
// and reads every message, as a Foxglove window showing everything would;
// prints the count per topic when `ms` have passed.
async function all(url, ms) {
  limitTo(ms);
  const s = connect(url);
  await until(() => s.serverInfo && s.channels.size > 0, 10000, "channels");
  const subscribed = new Map();
  const counts = {};
  const subscribeNew = () => {
    for (const [topic, ch] of s.channels) {
      if (subscribed.has(topic)) continue;
      subscribed.set(topic, s.client.subscribe(ch.id));
      counts[topic] = 0;
    }
  };
  s.client.on("advertise", subscribeNew);
  subscribeNew();
  const topicOf = new Map();
  s.client.on("message", (m) => {
    if (!topicOf.has(m.subscriptionId)) {
      for (const [t, id] of subscribed) if (id === m.subscriptionId) topicOf.set(id, t);
    }
    const t = topicOf.get(m.subscriptionId);
    if (t !== undefined) counts[t]++;
  });
  say({ subscribed: [...subscribed.keys()].sort() });
  await new Promise((r) => setTimeout(r, ms));
  say({ counts, statuses: s.statuses });
  s.client.close();
}

// A camera's ring notices (`notice`, whose `seq` numbers the frames) and
// its frames as foxglove.RawImage (`notice`/image): from the first notice
// on, for `ms`, counts the frames announced and the images delivered.
async function camera(url, notice, ms) {
  limitTo(ms);
  const s = connect(url);
  const image = `${notice}/image`;
  const n = await until(() => s.channels.get(notice), 10000, `channel ${notice}`);
  const i = await until(() => s.channels.get(image), 10000, `channel ${image}`);
  const subN = s.client.subscribe(n.id);
  const subI = s.client.subscribe(i.id);
  const st = { first: null, last: null, notices: 0, images: 0, bytes: 0, started: 0, done: false, width: 0, height: 0 };
  s.client.on("message", (m) => {
    if (st.done) return;
    if (m.subscriptionId === subN) {
      const seq = Number(decode(m.data).seq);
      if (st.first === null) {
        st.first = seq;
        st.started = Date.now();
        say({ counting: true, first: seq });
      }
      st.last = seq;
      st.notices++;
    } else if (m.subscriptionId === subI && st.first !== null) {
      st.images++;
      st.bytes += m.data.byteLength;
      if (st.width === 0) {
        const img = decode(m.data);
        st.width = img.width;
        st.height = img.height;
      }
    }
  });
  await until(() => st.first !== null, 10000, "a first frame");
  await new Promise((r) => setTimeout(r, ms));
  st.done = true;
  const seconds = (Date.now() - st.started) / 1000;
  say({
    seconds,
    announced: st.last - st.first + 1,
    notices: st.notices,
    images: st.images,
    bytes: st.bytes,
    width: st.width,
    height: st.height,
    statuses: s.statuses,
  });
  s.client.close();
  process.exit(0);
}

// The services advertised once connected (the server sends them with its
// serverInfo, in the same batch: a moment after it they are all known).
async function services(url) {
  const s = connect(url);
  await until(() => s.serverInfo, 10000, "serverInfo");
  await new Promise((r) => setTimeout(r, 100));
  say({ capabilities: s.serverInfo.capabilities, services: [...s.services.keys()].sort() });
  s.client.close();
  process.exit(0);
}

// Calls SERVICE with each request (JSON text, sent as is: a bad one too),
// all at once, and prints the advertisement and then each call's end: the
// answer (decoded) or the failure's message.
async function call(url, name, requests) {
  const s = connect(url);
  const service = await until(() => s.serverInfo && s.services.get(name), 10000, `service ${name}`);
  say({ capabilities: s.serverInfo.capabilities, service });
  const ends = new Map();
  s.client.on("serviceCallResponse", (r) => {
    if (r.serviceId === service.id) ends.set(r.callId, { encoding: r.encoding, response: decode(r.data) });
  });
  s.client.on("serviceCallFailure", (f) => {
    if (f.serviceId === service.id) ends.set(f.callId, { failure: f.message });
  });
  requests.forEach((text, i) => {
    const data = new TextEncoder().encode(text);
    s.client.sendServiceCallRequest({ serviceId: service.id, callId: i + 1, encoding: "json", data });
  });
  await until(() => ends.size >= requests.length, 15000, `the ends of ${requests.length} calls`);
  say({ calls: requests.map((_, i) => ends.get(i + 1)), statuses: s.statuses });
  s.client.close();
  process.exit(0);
}

const [scenario, ...args] = process.argv.slice(2);
const run = {
  watch: () => watch(args[0], args[1], args[2], Number(args[3])),
  refused: () => refused(args[0], args[1], args[2]),
  stall: () => stall(args[0], args[1], Number(args[2])),
  params: () => params(args[0], args[1], args[2], args[3]),
  graph: () => graph(args[0], args[1], args[2]),
  publish: () => publish(args[0], args[1], args[2], Number(args[3])),
  cycles: () => cycles(args[0], args[1], Number(args[2])),
  drive: () => drive(args[0], args[1], args[2], args[3]),
  teleop: () => teleop(args[0], args[1], Number(args[2]), Number(args[3]), Number(args[4]), args[5]),
  idle: () => idle(args[0], Number(args[1])),
  all: () => all(args[0], Number(args[1])),
  camera: () => camera(args[0], args[1], Number(args[2])),
  services: () => services(args[0]),
  call: () => call(args[0], args[1], args.slice(2)),
}[scenario];
if (!run) fail(`unknown scenario ${scenario}`);
Promise.resolve(run()).catch(fail);
