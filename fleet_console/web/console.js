// The fleet console's page: joins the fleet's Coaty bus as an MQTT client over a WebSocket (the console server
// passes the bytes to the broker), with the login typed here; draws what fleet_model holds; an operator login
// removes, confirms or adds obstacles as Coaty Advertises under its own identity. The broker's ACL decides what
// a login may publish: a read-only login's action never reaches a robot, and the page says so.
"use strict";

const $ = id => document.getElementById(id);
const C = { config: null, client: null, name: "", identity: "", role: "", password: "", connected: false,
            model: new FleetModel(), pending: new Map(), shownAt: {}, goneAt: {}, shown: new Set(),
            actions: [], mapImage: null, mapVersion: -1, diagnostics: [] };
window.fleetConsole = C;

function setStatus(text, kind) {
  const el = $("status"); el.textContent = text; el.className = "status " + (kind || "info");
}
function uuid4() {
  if (window.crypto && crypto.randomUUID) return crypto.randomUUID();
  const b = crypto.getRandomValues(new Uint8Array(16)); b[6] = (b[6] & 0x0f) | 0x40; b[8] = (b[8] & 0x3f) | 0x80;
  const h = Array.from(b, x => x.toString(16).padStart(2, "0")).join("");
  return h.slice(0, 8) + "-" + h.slice(8, 12) + "-" + h.slice(12, 16) + "-" + h.slice(16, 20) + "-" + h.slice(20);
}
function topic(event, corr) {
  return "coaty/3/" + C.config.namespace + "/" + event + "/" + C.identity + (corr ? "/" + corr : "");
}

async function loadConfig() {
  try {
    const r = await fetch("/config.json", { cache: "no-store" });
    C.config = await r.json();
  } catch (e) { setStatus("The console server does not answer: " + e, "error"); return; }
  document.title = C.config.title;
  $("map-error").textContent = C.config.mapError ? "Map: " + C.config.mapError : "";
  if (C.config.map && C.config.map.version !== C.mapVersion) {
    const img = new Image();
    img.onload = () => { C.mapImage = img; C.mapVersion = C.config.map.version; render(); };
    img.onerror = () => { $("map-error").textContent = "Map: the map image cannot be loaded"; };
    img.src = C.config.map.url + "?v=" + C.config.map.version;
  }
}

async function login(name, password) {
  name = (name || "").trim();
  if (!name || !password) { setStatus("Give a login name and its password.", "error"); return; }
  if (C.client) { C.client.end(true); C.client = null; }
  let who;
  try {
    const r = await fetch("/identity?name=" + encodeURIComponent(name));
    who = await r.json();
    if (!r.ok) { setStatus("Login refused: " + who.error, "error"); return; }
  } catch (e) { setStatus("The console server does not answer: " + e, "error"); return; }
  Object.assign(C, { name, identity: who.identity, role: who.role || "unknown", password, connected: false });
  $("role").textContent = name + " (" + (who.role || "role not known here") + ")";
  setStatus("Connecting to the fleet's broker as " + name + " ...", "info");
  const url = (location.protocol === "https:" ? "wss://" : "ws://") + location.host + C.config.wsPath;
  const will = { topic: topic("DAD"), payload: JSON.stringify({ objectIds: [C.identity] }), qos: 0, retain: false };
  const client = mqtt.connect(url, { username: name, password, clean: true, keepalive: 60, reconnectPeriod: 2000,
    connectTimeout: 10000, protocolVersion: 4,
    clientId: "Coaty" + C.identity.replace(/-/g, "").slice(0, 8) + uuid4().replace(/-/g, "").slice(0, 10), will });
  C.client = client;
  client.on("connect", () => {
    C.connected = true;
    setStatus("Logged in as " + name + (C.role === "viewer" ? " (read-only)" : C.role === "operator" ? " (operator)" : ""), "ok");
    client.subscribe("coaty/3/" + C.config.namespace + "/#", { qos: 0 }, err => {
      if (err) { setStatus("Subscription refused: " + err.message, "error"); return; }
      const identity = { objectType: "coaty.Identity", coreType: "Identity", objectId: C.identity, name: "console " + name };
      client.publish(topic("ADV:Identity"), JSON.stringify({ object: identity }));
      discover();
    });
    render();
  });
  client.on("message", (t, payload) => onMessage(t, payload));
  client.on("error", err => {
    if (err && (err.code === 4 || err.code === 5)) {
      setStatus("Login refused by the fleet's broker: wrong name or password for '" + name + "' (" + err.message + ")", "error");
      client.refused = true;
      client.end(true);
    } else {
      setStatus("Broker connection problem: " + (err && err.message ? err.message : err), "error");
    }
  });
  client.on("close", () => {
    if (C.connected) setStatus("Connection to the fleet's broker lost; reconnecting ...", "error");
    else if (!client.refused && C.client === client)
      setStatus("The fleet's broker cannot be reached through the console (" + url + "); retrying every 2 s ...", "error");
    C.connected = false;
  });
}

function discover() {
  const corr = uuid4();
  C.pending.set(corr, Date.now());
  C.client.publish(topic("DSC", corr), JSON.stringify({ objectTypes: [C.config.objectType] }));
}

async function onMessage(t, payload) {
  const parts = t.split("/");
  try {
    if (parts.length < 5 || parts[0] !== "coaty" || parts[1] !== "3") throw new BadInput("invalid_topic", "not a Coaty v3 topic");
    if (payload.length > 1048576) throw new BadInput("oversized", payload.length + " bytes");
    const event = parts[3], sourceId = parts[4];
    const relevant = event.startsWith("ADV:") || event === "DAD" || event.startsWith("CHN:org.fleetsharing.") || event === "RSV";
    if (!relevant) return;
    let body;
    try { body = JSON.parse(new TextDecoder("utf-8", { fatal: true }).decode(payload)); }
    catch (e) { throw new BadInput("invalid_json", "payload is not UTF-8 JSON"); }
    if (!body || typeof body !== "object") throw new BadInput("wrong_type", "payload is not a JSON object");
    const m = C.model, ot = C.config.objectType;
    if (sourceId === C.identity) ackAction(body);
    if (event === "ADV::" + ot || event.startsWith("ADV::" + ot + ".area_")) {
      m.apply(await obstacleFrom(body.object), "observation", "live");
    } else if (event === "ADV:Identity") {
      if (body.object && typeof body.object.name === "string") m.identities.set(sourceId, body.object.name.slice(0, 80));
    } else if (event.startsWith("ADV::org.fleetsharing.RobotFootprint")) {
      m.footprint(body.object || {});
    } else if (event === "DAD") {
      if (Array.isArray(body.objectIds)) m.deadvertise(body.objectIds);
    } else if (event === "CHN:org.fleetsharing.Heartbeat") {
      m.heartbeat(body.object || {});
    } else if (event === "CHN:org.fleetsharing.ObstacleRenewals") {
      const o = body.object || {};
      if (!Array.isArray(o.obstacles)) throw new BadInput("wrong_type", "renewals without obstacles");
      for (const e of o.obstacles.slice(0, 10000)) {
        if (!Array.isArray(e) || e.length !== 7) throw new BadInput("wrong_type", "renewal entry is not 7 fields");
        m.apply(await obstacleFrom({ uuid: e[0], version: e[1], stamp: e[2], deadline: e[3], rectangle: e[4],
          markedIndexes: e[5], clearedIndexes: e[6], source: o.source, frameId: o.frameId, resolution: o.resolution,
          origin: o.origin, size: o.size }), "observation", "renewal");
      }
    } else if (event === "RSV" && parts.length === 6 && C.pending.has(parts[5])) {
      const objects = [body.object].concat(Array.isArray(body.relatedObjects) ? body.relatedObjects : []);
      const from = m.identities.get(sourceId) || sourceId.slice(0, 8);
      for (const o of objects) {
        if (o && o.objectType === ot) m.apply(await obstacleFrom(o), "copy", "resolve from " + from);
      }
    }
  } catch (e) {
    C.model.drop(e.reason || "internal_error", t.slice(0, 120), e.message);
  }
  scheduleRender();
}

// ---------------------------------------------------------------- operator actions
function obstacleObject(e, version, marked, cleared, deadline) {
  const g = e.geometry;
  return { objectType: C.config.objectType, coreType: "CoatyObject", objectId: e.uuid, name: e.uuid.slice(0, 8),
           uuid: e.uuid, source: C.name, version, stamp: C.model.fleetNow(), frameId: g.frameId,
           deadline: Math.max(1, Math.floor(deadline)), rectangle: e.rectangle, resolution: g.resolution,
           origin: g.origin, size: g.size, markedIndexes: marked, clearedIndexes: cleared };
}

function act(kind, object) {
  const status = $("action-status");
  if (!C.connected) { status.textContent = "Not logged in: nothing was sent."; status.className = "status error"; return null; }
  const action = { kind, uuid: object.uuid, version: object.version, sentAt: Date.now(), acked: false };
  C.actions.push(action);
  C.client.publish(topic("ADV::" + C.config.objectType), JSON.stringify({ object }));
  status.textContent = kind + " " + object.uuid.slice(0, 8) + ": sent, waiting for the broker ..."; status.className = "status info";
  setTimeout(() => {
    if (!action.acked) {
      action.refused = true;
      status.textContent = kind + " " + object.uuid.slice(0, 8) + " refused: the broker did not take it; your login '" +
        C.name + "' may not change obstacles (read-only)";
      status.className = "status error";
    }
  }, 2000);
  return action;
}

function ackAction(body) {
  const o = body && body.object;
  if (!o) return;
  for (const a of C.actions) {
    if (!a.acked && a.uuid === o.uuid && a.version === o.version) {
      a.acked = true; a.ackedAt = Date.now();
      const status = $("action-status");
      status.textContent = a.kind + " " + a.uuid.slice(0, 8) + " taken by the broker: every robot applies it, attributed to " + C.name;
      status.className = "status ok";
      C.model.note("operator", a.uuid, C.name, a.kind);
    }
  }
}

// An operator's update outranks what robots send meanwhile: the robots keep monitoring the obstacle, and an
// update of theirs in flight with the same version would win the tie (its source sorts after most names).
// Robots' later updates take a version above it, as they would after any update they hear. The margin is the
// rules of authority's OPERATOR_VERSION_MARGIN (sharing_msgs.authority), which the server gives in /config.json;
// every handler's max_version_step is at least twice it, so no robot refuses the jump as implausible.
const versionMargin = () => C.config.versionMargin;
C.remove = uuid => {
  const e = C.model.obstacles.get(uuid);
  if (!e || e.present === 0) return null;
  // every cell ever heard of, not only those present here: a robot may still hold one this page saw cleared
  const cells = Array.from(e.cells.keys()).sort((a, b) => a - b);
  return act("remove", obstacleObject(e, e.maxVersion + versionMargin(), [], cells, (e.expiresAt - Date.now()) / 1000));
};
C.confirm = uuid => {
  const e = C.model.obstacles.get(uuid);
  if (!e || e.present === 0) return null;
  const present = Array.from(e.cells).filter(([, c]) => c.on).map(([i]) => i).sort((a, b) => a - b);
  return act("confirm", obstacleObject(e, e.maxVersion + versionMargin(), present, [], C.config.obstacleDuration));
};
C.add = rect => {
  const g = C.config.map ? { resolution: C.config.map.resolution, origin: C.config.map.origin,
                             size: [C.config.map.width, C.config.map.height], frameId: "map" }
                         : (C.model.listed()[0] || {}).geometry;
  const status = $("action-status");
  if (!g) { status.textContent = "Add: no map and no obstacle known, so no grid to put cells on."; status.className = "status error"; return null; }
  if (!(rect.every(Number.isFinite) && rect[0] < rect[2] && rect[1] < rect[3])) {
    status.textContent = "Add: give min x < max x and min y < max y, in metres."; status.className = "status error"; return null;
  }
  const cells = [];
  for (let y = 0; y < g.size[1]; y++) {
    const wy = g.origin[1] + (y + 0.5) * g.resolution;
    if (wy < rect[1] || wy > rect[3]) continue;
    for (let x = 0; x < g.size[0]; x++) {
      const wx = g.origin[0] + (x + 0.5) * g.resolution;
      if (wx >= rect[0] && wx <= rect[2]) cells.push(y * g.size[0] + x);
    }
  }
  if (!cells.length) { status.textContent = "Add: the rectangle covers no cell of the map."; status.className = "status error"; return null; }
  const e = { uuid: uuid4(), geometry: g, rectangle: rect };
  return act("add", obstacleObject(e, 1, cells, [], C.config.obstacleDuration));
};
