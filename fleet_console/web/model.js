// The fleet as the console hears it on the Coaty bus: obstacles (cells with the (version, source) of the update
// that last set them, the rule every robot's handler applies, so the page holds what the robots hold), robots'
// footprints and heartbeats, a timeline, and what was dropped and why. No DOM and no MQTT here.
"use strict";

const MAX_TIMELINE = 300;
const UUID_RE = /^[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}$/;

class BadInput extends Error {
  constructor(reason, text) { super(text); this.reason = reason; }
}

function need(cond, reason, text) { if (!cond) throw new BadInput(reason, text); }
function isNum(v) { return typeof v === "number" && Number.isFinite(v); }
function isInt(v) { return Number.isInteger(v) && v >= 0; }

// compact indexes (coaty_bridge.compact): base64 of LEB128 gaps, or "z:" + base64(raw deflate of them)
async function decodeIndexes(value, limit) {
  if (Array.isArray(value)) {
    for (const v of value) need(isInt(v) && v < limit, "out_of_range", "index " + String(v).slice(0, 20) + " outside the grid");
    return Array.from(new Set(value)).sort((a, b) => a - b);
  }
  need(typeof value === "string", "wrong_type", "indexes are neither a list nor a compact string");
  const deflated = value.startsWith("z:");
  let bytes;
  try {
    bytes = Uint8Array.from(atob(deflated ? value.slice(2) : value), c => c.charCodeAt(0));
  } catch (e) { throw new BadInput("wrong_type", "compact indexes are not base64"); }
  if (deflated) {
    need(bytes.length < 4000000, "too_many_indexes", "compact indexes too long");
    const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream("deflate-raw"));
    try { bytes = new Uint8Array(await new Response(stream).arrayBuffer()); }
    catch (e) { throw new BadInput("wrong_type", "compact indexes are not raw deflate"); }
  }
  const out = [];
  let value_ = null, delta = 0, shift = 0, used = 0;
  for (const byte of bytes) {
    delta += (byte & 0x7f) * Math.pow(2, shift); shift += 7; used += 1;
    need(used <= 5, "out_of_range", "varint longer than 5 bytes");
    if (byte & 0x80) continue;
    need(value_ === null || delta > 0, "out_of_range", "repeated index");
    value_ = value_ === null ? delta : value_ + delta;
    need(value_ < limit, "out_of_range", "compact index " + value_ + " outside the grid");
    out.push(value_); delta = 0; shift = 0; used = 0;
  }
  need(used === 0, "out_of_range", "compact indexes end inside a varint");
  return out;
}

// an obstacle object (coaty_bridge README, "Obstacle object") -> a checked update
async function obstacleFrom(o) {
  need(o && typeof o === "object", "wrong_type", "object is not a JSON object");
  need(typeof o.uuid === "string" && UUID_RE.test(o.uuid), "missing_field", "uuid is not a UUID");
  need(typeof o.source === "string" && o.source.length > 0 && o.source.length <= 256, "missing_field", "source missing");
  need(isInt(o.version) && o.version >= 1, "out_of_range", "version must be a whole number >= 1");
  need(isNum(o.stamp) && isInt(o.deadline), "out_of_range", "stamp or deadline is not a number");
  need(Array.isArray(o.rectangle) && o.rectangle.length === 4 && o.rectangle.every(isNum), "wrong_type", "rectangle is not 4 numbers");
  need(isNum(o.resolution) && o.resolution > 0, "out_of_range", "resolution must be > 0");
  need(Array.isArray(o.origin) && o.origin.length === 2 && o.origin.every(isNum), "wrong_type", "origin is not [x, y]");
  need(Array.isArray(o.size) && o.size.length === 2 && o.size.every(v => isInt(v) && v >= 1), "wrong_type", "size is not 2 whole numbers");
  const limit = o.size[0] * o.size[1];
  need(limit <= 4294967296, "out_of_range", "grid too large");
  const marked = await decodeIndexes(o.markedIndexes === undefined ? [] : o.markedIndexes, limit);
  const cleared = await decodeIndexes(o.clearedIndexes === undefined ? [] : o.clearedIndexes, limit);
  need(marked.length + cleared.length > 0, "missing_field", "neither marked nor cleared cells");
  return { uuid: o.uuid, source: o.source, version: o.version, stamp: o.stamp, frameId: String(o.frameId || "map"),
           deadline: o.deadline, rectangle: o.rectangle.slice(), resolution: o.resolution, origin: o.origin.slice(),
           size: o.size.slice(), marked, cleared };
}

function newer(a, b) {   // (version, source) pairs: is a greater than b?
  return a.v > b.v || (a.v === b.v && a.src > b.src);
}

class FleetModel {
  constructor(clock) {
    this.clock = clock || (() => Date.now());
    this.obstacles = new Map();   // uuid -> entry (kept after it empties, so an older copy cannot revive it)
    this.robots = new Map();      // robot name -> {footprint, stamp, heardAt, heartbeat}
    this.identities = new Map();  // sourceId -> name
    this.timeline = [];
    this.drops = new Map();       // reason -> {count, last}
    this.fleetStamp = null;       // newest stamp a robot sent, and when it arrived: the fleet's clock
  }

  note(kind, uuid, by, text) {
    this.timeline.unshift({ time: this.clock(), kind, uuid, by, text });
    if (this.timeline.length > MAX_TIMELINE) this.timeline.length = MAX_TIMELINE;
  }

  drop(reason, topic, text) {
    const d = this.drops.get(reason) || { count: 0, last: "" };
    d.count += 1; d.last = (topic + ": " + text).slice(0, 300);
    this.drops.set(reason, d);
  }

  seeStamp(stamp) {
    if (isNum(stamp) && (this.fleetStamp === null || stamp > this.fleetStamp.stamp))
      this.fleetStamp = { stamp, at: this.clock() };
  }

  // what to stamp an operator's update with: the fleet's clock (simulated or not), never ahead of it
  fleetNow() {
    if (this.fleetStamp === null) return this.clock() / 1000;
    return this.fleetStamp.stamp + Math.min(1.0, (this.clock() - this.fleetStamp.at) / 1000);
  }

  // an update as every handler applies it: marks and clears, the greater (version, source) of each cell wins
  apply(u, how, via) {
    const now = this.clock();
    let e = this.obstacles.get(u.uuid);
    const fresh = !e;
    if (fresh) {
      if (u.marked.length === 0) return;   // a clear of an obstacle we never held
      e = { uuid: u.uuid, creator: u.source, cells: new Map(), present: 0, rectangle: u.rectangle.slice(),
            geometry: { resolution: u.resolution, origin: u.origin, size: u.size, frameId: u.frameId },
            firstSeen: now, sources: new Set(), maxVersion: 0, expiresAt: now + u.deadline * 1000,
            lastObservation: null, lastBy: u.source, via: new Set() };
      this.obstacles.set(u.uuid, e);
    }
    const wasPresent = e.present > 0;
    if (u.version === 1) e.creator = u.source;
    const stamp = { v: u.version, src: u.source };
    for (const c of u.marked) {
      const old = e.cells.get(c);
      if (!old || newer(stamp, old)) e.cells.set(c, { v: u.version, src: u.source, on: true });
    }
    for (const c of u.cleared) {
      const old = e.cells.get(c);
      if (!old || newer(stamp, old)) e.cells.set(c, { v: u.version, src: u.source, on: false });
    }
    e.present = 0;
    for (const cell of e.cells.values()) if (cell.on) e.present += 1;
    for (let i = 0; i < 2; i++) e.rectangle[i] = Math.min(e.rectangle[i], u.rectangle[i]);
    for (let i = 2; i < 4; i++) e.rectangle[i] = Math.max(e.rectangle[i], u.rectangle[i]);
    e.maxVersion = Math.max(e.maxVersion, u.version);
    e.sources.add(u.source); e.via.add(via); e.lastBy = u.source;
    const until = now + u.deadline * 1000;
    if (how === "observation" && u.marked.length > 0) {
      e.expiresAt = fresh ? until : Math.max(e.expiresAt, until);
      e.lastObservation = { stamp: u.stamp, at: now, by: u.source };
    } else if (!fresh) {
      e.expiresAt = Math.min(e.expiresAt, until);   // a clear or a copy never lengthens the lease
    }
    this.seeStamp(u.stamp);
    if (!wasPresent && e.present > 0) this.note(fresh ? "share" : "share", u.uuid, u.source, (fresh ? "shared" : "back") + ", " + e.present + " cells" + (via !== "live" ? " (" + via + ")" : ""));
    else if (wasPresent && e.present === 0) this.note("clear", u.uuid, u.source, "every cell cleared: gone from the fleet");
    else if (e.present > 0) this.note("update", u.uuid, u.source, "v" + u.version + ": +" + u.marked.length + " / -" + u.cleared.length + " cells");
  }

  expire() {
    const now = this.clock();
    for (const [uuid, e] of this.obstacles) {
      if (now >= e.expiresAt) {
        if (e.present > 0) this.note("expiry", uuid, "", "lease ran out");
        this.obstacles.delete(uuid);
      }
    }
    for (const [name, r] of this.robots) {
      if (r.footprint && now - r.heardAt > Math.max(10000, (r.validFor || 0) * 1000)) r.footprint = null;
    }
  }

  listed() {
    return Array.from(this.obstacles.values()).filter(e => e.present > 0).sort((a, b) => a.firstSeen - b.firstSeen);
  }

  robot(name) {
    if (!this.robots.has(name)) this.robots.set(name, { name, footprint: null, heardAt: 0, heartbeat: null, beatAt: 0 });
    return this.robots.get(name);
  }

  footprint(o) {
    need(typeof o.robot === "string" && o.robot.length > 0, "missing_field", "footprint without robot");
    need(Array.isArray(o.footprint) && o.footprint.length >= 1 && o.footprint.length <= 100 &&
         o.footprint.every(p => Array.isArray(p) && p.length === 2 && p.every(isNum)), "wrong_type", "footprint is not [[x, y], ...]");
    const r = this.robot(o.robot);
    r.footprint = o.footprint; r.heardAt = this.clock(); r.objectId = o.objectId;
    r.validFor = isNum(o.validFor) ? o.validFor : 0;
    r.velocity = Array.isArray(o.velocity) && o.velocity.length === 2 && o.velocity.every(isNum) ? o.velocity : [0, 0];
    this.seeStamp(o.stamp);
  }

  // where robot r is now: a driving robot's dead-reckoned advert (velocity and validFor) moved on from when it was
  // heard, for at most validFor / 2.5 s (the sender's advert interval), as the bridges do (coaty_bridge footprint.py)
  footprintAt(r) {
    if (!r.footprint) return null;
    const [vx, vy] = r.velocity || [0, 0];
    if (!(r.validFor > 0) || (vx === 0 && vy === 0)) return r.footprint;
    const dt = Math.min(Math.max((this.clock() - r.heardAt) / 1000, 0), r.validFor / 2.5);
    return r.footprint.map(([x, y]) => [x + vx * dt, y + vy * dt]);
  }

  heartbeat(o) {
    need(typeof o.robot === "string" && o.robot.length > 0, "missing_field", "heartbeat without robot");
    const r = this.robot(o.robot);
    r.heartbeat = { interval: isNum(o.interval) ? o.interval : 1, misses: Array.isArray(o.misses) ? o.misses.slice(0, 50) : [],
                    heard: Array.isArray(o.heard) ? o.heard.length : null, leaving: o.leaving === true };
    r.beatAt = this.clock();
  }

  deadvertise(ids) {
    for (const r of this.robots.values()) if (ids.includes(r.objectId)) r.footprint = null;
  }
}

if (typeof module !== "undefined") module.exports = { FleetModel, obstacleFrom, decodeIndexes, BadInput };
