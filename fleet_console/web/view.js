// Drawing: the map with obstacles' cells, rectangles and robots' footprints; the obstacle table, the timeline,
// the fleet's health and what was dropped. Text goes in with textContent only: nothing from the bus is markup.
"use strict";

const COLOURS = ["#d62728", "#1f77b4", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf"];
function colourOf(name) {
  let h = 0; for (const ch of String(name)) h = (h * 31 + ch.charCodeAt(0)) >>> 0;
  return COLOURS[h % COLOURS.length];
}
function el(tag, text, cls) { const e = document.createElement(tag); if (text !== undefined) e.textContent = text; if (cls) e.className = cls; return e; }
function age(ms) { const s = Math.max(0, ms / 1000); return s < 90 ? s.toFixed(1) + " s" : (s / 60).toFixed(1) + " min"; }
function clock(ms) { return new Date(ms).toLocaleTimeString(); }

let renderQueued = false;
function scheduleRender() { if (!renderQueued) { renderQueued = true; setTimeout(() => { renderQueued = false; render(); }, 0); } }

function worldBox() {
  const m = C.config && C.config.map;
  if (m) return [m.origin[0], m.origin[1], m.origin[0] + m.width * m.resolution, m.origin[1] + m.height * m.resolution];
  const box = [Infinity, Infinity, -Infinity, -Infinity];
  for (const e of C.model.obstacles.values()) {
    const g = e.geometry;
    box[0] = Math.min(box[0], g.origin[0]); box[1] = Math.min(box[1], g.origin[1]);
    box[2] = Math.max(box[2], g.origin[0] + g.size[0] * g.resolution); box[3] = Math.max(box[3], g.origin[1] + g.size[1] * g.resolution);
  }
  return Number.isFinite(box[0]) ? box : [0, 0, 10, 10];
}

function drawMap() {
  const canvas = $("map"), ctx = canvas.getContext("2d");
  const box = worldBox(), scale = Math.min(canvas.width / (box[2] - box[0]), canvas.height / (box[3] - box[1]));
  const px = x => (x - box[0]) * scale, py = y => canvas.height - (y - box[1]) * scale;
  ctx.fillStyle = "#ddd"; ctx.fillRect(0, 0, canvas.width, canvas.height);
  if (C.mapImage) ctx.drawImage(C.mapImage, 0, canvas.height - (box[3] - box[1]) * scale, (box[2] - box[0]) * scale, (box[3] - box[1]) * scale);
  for (const e of C.model.listed()) {
    const g = e.geometry, size = Math.max(2, g.resolution * scale);
    ctx.fillStyle = colourOf(e.creator);
    for (const [i, cell] of e.cells) {
      if (!cell.on) continue;
      const x = g.origin[0] + (i % g.size[0]) * g.resolution, y = g.origin[1] + Math.floor(i / g.size[0]) * g.resolution;
      ctx.fillRect(px(x), py(y) - size, size, size);
    }
    ctx.strokeStyle = colourOf(e.creator); ctx.setLineDash([4, 3]); ctx.lineWidth = 1;
    ctx.strokeRect(px(e.rectangle[0]), py(e.rectangle[3]), (e.rectangle[2] - e.rectangle[0]) * scale, (e.rectangle[3] - e.rectangle[1]) * scale);
    ctx.setLineDash([]); ctx.fillStyle = "#000"; ctx.font = "12px sans-serif";
    ctx.fillText(e.uuid.slice(0, 8), px(e.rectangle[0]), py(e.rectangle[3]) - 3);
  }
  for (const r of C.model.robots.values()) {
    const points = C.model.footprintAt(r);
    if (!points) continue;
    ctx.beginPath();
    points.forEach(([x, y], k) => k ? ctx.lineTo(px(x), py(y)) : ctx.moveTo(px(x), py(y)));
    ctx.closePath(); ctx.fillStyle = "rgba(31,119,180,0.35)"; ctx.fill(); ctx.strokeStyle = "#1f4e79"; ctx.lineWidth = 2; ctx.stroke();
    const cx = points.reduce((s, p) => s + p[0], 0) / points.length, cy = points.reduce((s, p) => s + p[1], 0) / points.length;
    ctx.fillStyle = "#1f4e79"; ctx.font = "bold 12px sans-serif"; ctx.fillText(r.name, px(cx) + 8, py(cy) - 8);
  }
}

function drawObstacles() {
  const body = $("obstacles-body"), now = Date.now(), listed = C.model.listed();
  body.textContent = "";
  const mayAct = C.connected && C.role !== "viewer";
  for (const e of listed) {
    const tr = el("tr"); tr.id = "ob-" + e.uuid; tr.dataset.uuid = e.uuid;
    const obs = e.lastObservation;
    tr.append(el("td", e.uuid.slice(0, 8), "mono"), el("td", e.creator), el("td", clock(e.firstSeen)),
      el("td", obs ? obs.by + ", " + age(now - obs.at) + " ago" : "none seen live"), el("td", age(e.expiresAt - now)),
      el("td", String(e.present)),
      el("td", "v" + e.maxVersion + " by " + Array.from(e.sources).join(", ") + "; " + Array.from(e.via).join(", ")));
    const td = el("td");
    for (const [kind, fn] of [["Confirm", C.confirm], ["Remove", C.remove]]) {
      const b = el("button", kind, kind.toLowerCase());
      b.disabled = !mayAct; b.title = mayAct ? kind + " as " + C.name : "needs an operator login";
      b.onclick = () => fn(e.uuid);
      td.append(b);
    }
    tr.append(td); body.append(tr);
    if (!C.shown.has(e.uuid)) { C.shown.add(e.uuid); C.shownAt[e.uuid] = now; }
  }
  const live = new Set(listed.map(e => e.uuid));
  for (const u of C.shown) if (!live.has(u)) { C.shown.delete(u); C.goneAt[u] = now; }
  $("obstacle-count").textContent = listed.length + " shared obstacle(s)";
  $("add-btn").disabled = !mayAct;
}

function drawTimeline() {
  const ul = $("timeline"); ul.textContent = "";
  for (const t of C.model.timeline.slice(0, 60)) {
    const li = el("li", clock(t.time) + "  " + t.kind.padEnd(8) + " " + (t.uuid || "").slice(0, 8) + "  " + (t.by ? t.by + ": " : "") + t.text, "t-" + t.kind);
    ul.append(li);
  }
}

function drawHealth() {
  const body = $("health-body"), now = Date.now(); body.textContent = "";
  for (const r of Array.from(C.model.robots.values()).sort((a, b) => a.name.localeCompare(b.name))) {
    const hb = r.heartbeat, silent = hb ? (now - r.beatAt) / 1000 : null;
    const partition = hb && silent > 3 * Math.max(1, hb.interval);
    const state = !hb ? "no heartbeat heard" : hb.leaving ? "left" : partition ? "PARTITION: silent " + silent.toFixed(0) + " s"
                : hb.misses.length ? "misses " + hb.misses.join(", ") : "ok";
    const tr = el("tr", undefined, partition || (hb && hb.misses.length) ? "warn" : "");
    tr.append(el("td", r.name), el("td", hb ? age(now - r.beatAt) + " ago (every " + hb.interval.toFixed(0) + " s)" : "-"),
              el("td", state), el("td", r.footprint ? age(now - r.heardAt) + " ago" : "-"));
    body.append(tr);
  }
  const diag = $("diagnostics-body"); diag.textContent = "";
  for (const d of C.diagnostics) {
    const level = ["OK", "WARN", "ERROR", "STALE"][d.level] || String(d.level);
    const drops = Object.entries(d.values || {}).filter(([k, v]) => k.startsWith("dropped") && v !== "0").map(([k, v]) => k + " " + v).slice(0, 6).join(", ");
    const tr = el("tr", undefined, d.level ? "warn" : "");
    tr.append(el("td", d.name), el("td", level), el("td", d.message), el("td", drops || "none"));
    diag.append(tr);
  }
  const errs = $("errors"); errs.textContent = "";
  for (const [reason, d] of C.model.drops) errs.append(el("li", reason + " x" + d.count + ": " + d.last));
}

function render() {
  if (!C.config) return;
  C.model.expire();
  try { drawMap(); } catch (e) { $("map-error").textContent = "Map: cannot draw: " + e.message; }
  drawObstacles(); drawTimeline(); drawHealth();
}

async function pollHealth() {
  if (!C.connected) return;
  try {
    const r = await fetch("/health.json", { headers: { "X-Fleet-Login": C.name + ":" + C.password }, cache: "no-store" });
    if (r.ok) C.diagnostics = (await r.json()).diagnostics || [];
  } catch (e) { /* the server is back on the next poll */ }
}

window.addEventListener("load", async () => {
  await loadConfig();
  $("login-form").addEventListener("submit", ev => { ev.preventDefault(); login($("name").value, $("password").value); });
  $("add-form").addEventListener("submit", ev => {
    ev.preventDefault();
    C.add(["add-minx", "add-miny", "add-maxx", "add-maxy"].map(id => parseFloat($(id).value)));
  });
  setInterval(render, 1000);
  setInterval(pollHealth, 2000);
  setInterval(loadConfig, 5000);
  render();
});
