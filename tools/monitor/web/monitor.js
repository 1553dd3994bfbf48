// SPDX-License-Identifier: Apache-2.0
// plumb monitor page: renders /api/state and follows /api/events (server-sent events).
"use strict";
(function () {
  const SVG = "http://www.w3.org/2000/svg";
  const params = new URLSearchParams(window.location.search);
  const token = params.get("token");
  const withToken = (path) => (token ? path + "?token=" + encodeURIComponent(token) : path);
  const $ = (id) => document.getElementById(id);
  let lastState = null;
  let seenFragments = new Set();

  function el(tag, attrs, text) {
    const e = document.createElementNS(SVG, tag);
    for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
    if (text !== undefined) e.textContent = text;
    return e;
  }
  function clear(node) { while (node.firstChild) node.removeChild(node.firstChild); }
  function fmtBytes(b) {
    if (b >= 1 << 30) return (b / (1 << 30)).toFixed(2) + " GiB";
    if (b >= 1 << 20) return (b / (1 << 20)).toFixed(1) + " MiB";
    if (b >= 1 << 10) return (b / (1 << 10)).toFixed(1) + " KiB";
    return b + " B";
  }
  function dl(rows) {
    const d = document.createElement("dl");
    for (const [k, v, cls] of rows) {
      const dt = document.createElement("dt"); dt.textContent = k;
      const dd = document.createElement("dd"); dd.textContent = v;
      if (cls) dd.className = cls;
      d.append(dt, dd);
    }
    return d;
  }
  function edgeColour(e) {
    if (!e.kept) return "#999";
    if (e.kind === "odometry") return "#4a6fa5";
    const w = Math.max(0, Math.min(1, e.line_process));
    return "hsl(" + Math.round(120 * w) + ", 70%, " + (45 - 7 * w).toFixed(0) + "%)";
  }
  function pts(list) { return list.map((p) => p[0] + "," + p[1]).join(" "); }

  function renderDevice(s) {
    const box = $("device");
    clear(box);
    const d = s.device;
    if (!d) { box.textContent = s.source.mode === "directory" ? "review of an output directory" : "no heartbeat yet"; box.className = "muted"; return; }
    box.className = "";
    const age = Date.now() / 1000 - d.received_unix_s;
    const stale = age > d.stale_after_s;
    const trackCls = d.tracking === "ok" ? "badge good" : d.tracking === "lost" || d.tracking === "no camera" ? "badge bad" : "badge warn";
    box.append(dl([
      ["tracking", d.tracking, trackCls],
      ["fps", d.fps.toFixed(1)],
      ["frames", d.frames_processed + " processed (" + (100 * d.processed_fraction).toFixed(0) + " % of the camera's)", d.processed_fraction < 0.95 ? "badge warn" : ""],
      ["dropped", String(d.frames_dropped), d.frames_dropped > 0 ? "badge warn" : ""],
      ["fragments", d.fragments_cut + " cut, " + d.fragments_acked + " acked"],
      ["spool", d.spool_fragments + " fragments, " + fmtBytes(d.spool_bytes)],
      ["memory", fmtBytes(d.memory_bytes)],
      ["session", String(d.session_id)],
      ["heartbeat", stale ? "stale (" + age.toFixed(0) + " s)" : "seq " + d.seq, stale ? "badge bad" : ""],
    ]));
  }

  function renderSide(s) {
    const link = $("link");
    clear(link);
    if (s.link) {
      link.className = "";
      link.append(dl([
        ["messages", String(s.link.messages)],
        ["chunks", String(s.link.chunks_received)],
        ["fragments", String(s.link.fragments_completed)],
        ["CRC failures", String(s.link.chunk_crc_failures + s.link.fragment_crc_failures)],
        ["malformed", String(s.link.malformed)],
      ]));
    } else { link.className = "muted"; link.textContent = "—"; }
    if (s.source.replay) {
      link.append(dl([["replay", s.source.replay.messages + " messages" + (s.source.replay.finished ? ", finished" : "")]]));
    }
    const cov = $("coverage");
    clear(cov);
    const c = s.coverage;
    cov.className = "";
    // The room's coverage is known only once the layout has closed the room with walls; before
    // that the fraction is of the hull of what was seen, which says nothing about the rest.
    let covered = "—";
    if (c.cells_of_interest && c.room_closed) covered = (100 * c.room_fraction).toFixed(1) + " % of the room";
    else if (c.cells_of_interest) covered = "unknown: room not closed";
    const rows = [
      ["covered", covered, c.room_closed ? "" : "badge warn"],
      ["gaps", c.num_gaps + " cells of " + c.cell_m.toFixed(2) + " m" + (c.room_closed ? "" : " (inside the seen area)")],
      ["region", c.region === "room_polygon" ? "room (layout)" : "hull of points"],
    ];
    if (c.wall_bounded_fraction !== null && c.wall_bounded_fraction !== undefined) {
      rows.push(["outline on walls", (100 * c.wall_bounded_fraction).toFixed(0) + " %"]);
    }
    cov.append(dl(rows));
    const lay = $("layout");
    clear(lay);
    if (s.layout) {
      lay.className = "";
      const walls = s.layout.planes.filter((p) => p.kind === "wall");
      lay.append(dl([
        ["walls", String(walls.length)],
        ["snapped", String(walls.filter((w) => w.manhattan_snapped).length)],
        ["ceiling", s.layout.ceiling_height_m === null ? "not seen" : s.layout.ceiling_height_m.toFixed(2) + " m"],
        ["polygon", s.layout.room_polygon_V.length + " corners"],
      ]));
    } else { lay.className = "muted"; lay.textContent = "no layout yet"; }
    const errs = $("errors");
    clear(errs);
    for (const m of s.errors) { const li = document.createElement("li"); li.textContent = m; errs.append(li); }
  }

  function renderLists(s) {
    const body = $("fragment-list").querySelector("tbody");
    clear(body);
    const now = new Set();
    for (const f of s.fragments.slice().reverse()) {
      const key = f.session + ":" + f.id;
      now.add(key);
      const tr = document.createElement("tr");
      tr.className = "fragment" + (seenFragments.has(key) ? "" : " new");
      tr.dataset.id = f.id;
      for (const v of [f.id, f.frames[0] + "–" + f.frames[1], f.num_points, f.pose_source, f.end, f.ack]) {
        const td = document.createElement("td"); td.textContent = String(v); tr.append(td);
      }
      body.append(tr);
    }
    seenFragments = now;
    $("fragment-count").textContent = String(s.fragments.length);
    const eb = $("edge-list").querySelector("tbody");
    clear(eb);
    for (const e of s.edges) {
      const tr = document.createElement("tr");
      tr.className = "edge " + e.kind;
      tr.dataset.source = e.source; tr.dataset.target = e.target;
      const state = e.provisional ? "provisional" : e.kept ? "kept" : "pruned: " + e.reason;
      for (const v of [e.source + "→" + e.target, e.kind, e.line_process.toFixed(2), e.overlap.toFixed(2),
                       (100 * e.inlier_rmse_m).toFixed(1) + " cm", state]) {
        const td = document.createElement("td"); td.textContent = String(v); tr.append(td);
      }
      tr.firstChild.style.borderLeft = "4px solid " + edgeColour(e);
      eb.append(tr);
    }
    $("edge-count").textContent = String(s.edges.length);
  }

  function renderMap(s) {
    const layers = {};
    for (const name of ["gaps", "room", "fragments", "trajectory", "edges", "nodes"]) {
      layers[name] = $("layer-" + name);
      clear(layers[name]);
    }
    let lo = [Infinity, Infinity], hi = [-Infinity, -Infinity];
    const grow = (p) => { lo = [Math.min(lo[0], p[0]), Math.min(lo[1], p[1])]; hi = [Math.max(hi[0], p[0]), Math.max(hi[1], p[1])]; };
    $("map-frame").textContent = s.view.frame === "layout" ? "(layout frame, floor plan)" : "(first camera frame, y up = -y camera)";

    const c = s.coverage;
    for (const [ix, iy] of c.gaps) {
      layers.gaps.append(el("rect", { class: "gap", x: c.origin_V[0] + ix * c.cell_m, y: c.origin_V[1] + iy * c.cell_m,
                                      width: c.cell_m, height: c.cell_m, fill: "rgba(229,62,62,0.30)" }));
    }
    if (s.layout) {
      const poly = s.layout.room_polygon_V;
      poly.forEach(grow);
      layers.room.append(el("polygon", { class: "room", points: pts(poly), fill: "rgba(45,55,72,0.04)", stroke: "#2d3748",
                                         "stroke-width": 2, "vector-effect": "non-scaling-stroke" }));
      for (const w of s.layout.walls_V) {
        layers.room.append(el("line", { class: "wall", x1: w.start_V[0], y1: w.start_V[1], x2: w.end_V[0], y2: w.end_V[1],
                                        stroke: w.manhattan_snapped ? "#2b6cb0" : "#2d3748", "stroke-width": 4,
                                        "stroke-opacity": 0.5, "vector-effect": "non-scaling-stroke" }));
      }
    }
    const pos = new Map();
    const newest = s.fragments.length ? s.fragments[s.fragments.length - 1].session : 0;
    s.fragments.forEach((f, i) => {
      const hue = (f.id * 47) % 360;
      if (f.outline_V.length >= 3) {
        f.outline_V.forEach(grow);
        const poly = el("polygon", { class: "fragment-outline", "data-id": f.id, points: pts(f.outline_V),
                                     fill: "hsla(" + hue + ",60%,55%,0.12)", stroke: "hsl(" + hue + ",60%,40%)",
                                     "stroke-width": 1, "vector-effect": "non-scaling-stroke" });
        poly.append(el("title", {}, "fragment " + f.id + ": frames " + f.frames[0] + "–" + f.frames[1] + ", " + f.num_points + " points"));
        layers.fragments.append(poly);
      }
      grow(f.position_V);
      if (f.session === newest) pos.set(f.id, f.position_V);
      layers.nodes.append(el("circle", { class: "fragment-node", "data-id": f.id, cx: f.position_V[0], cy: f.position_V[1],
                                         r: 4, fill: "hsl(" + hue + ",60%,40%)", "vector-effect": "non-scaling-stroke",
                                         transform: "" }));
    });
    if (s.trajectory_V.length > 1) {
      s.trajectory_V.forEach(grow);
      layers.trajectory.append(el("polyline", { class: "trajectory", points: pts(s.trajectory_V), fill: "none",
                                                stroke: "#718096", "stroke-width": 1, "vector-effect": "non-scaling-stroke" }));
    }
    for (const e of s.edges) {
      const a = pos.get(e.source), b = pos.get(e.target);
      if (!a || !b) continue;
      const attrs = { class: "edge " + e.kind + (e.kept ? "" : " pruned"), "data-source": e.source, "data-target": e.target,
                      x1: a[0], y1: a[1], x2: b[0], y2: b[1], stroke: edgeColour(e),
                      "stroke-width": e.kind === "loop" ? 1 + 2 * e.line_process : 2, "vector-effect": "non-scaling-stroke" };
      if (!e.kept || e.provisional) attrs["stroke-dasharray"] = e.kept ? "6 3" : "3 3";
      const line = el("line", attrs);
      line.append(el("title", {}, e.kind + " " + e.source + "→" + e.target + ", weight " + e.line_process.toFixed(2)));
      layers.edges.append(line);
    }
    if (!isFinite(lo[0])) { lo = [-2.5, -2.5]; hi = [2.5, 2.5]; }
    const m = 0.1 * Math.max(hi[0] - lo[0], hi[1] - lo[1], 1);
    // The world group flips y (scale(1,-1)), so the view box spans -hi.y .. -lo.y vertically.
    $("map").setAttribute("viewBox", [lo[0] - m, -hi[1] - m, hi[0] - lo[0] + 2 * m, hi[1] - lo[1] + 2 * m].join(" "));
    // Node circles keep a fixed screen size: r is in map units, so scale it with the view.
    const r = 0.008 * Math.max(hi[0] - lo[0], hi[1] - lo[1], 1);
    for (const cEl of layers.nodes.children) cEl.setAttribute("r", r);
  }

  function render(s) {
    // The first poll and the event stream race: a state older than the one shown (a slow
    // /api/state answer arriving after a newer event) must not replace it, or the page would
    // stay behind until the next change, which may never come.
    if (lastState && s.version < lastState.version) return;
    lastState = s;
    $("source").textContent = s.source.mode + (s.source.detail ? ": " + s.source.detail : "");
    $("version").textContent = "v" + s.version;
    renderDevice(s);
    renderSide(s);
    renderLists(s);
    renderMap(s);
    document.body.dataset.version = s.version;
  }

  function setConnection(cls, text) {
    const c = $("connection");
    c.textContent = text;
    c.className = "badge " + cls;
  }

  // What the connected page shows: "live" only for a live source; a replayed log or a folder
  // says so, and a folder whose run has ended (metrics.json written) reads "finished".
  function connectedBadge(s) {
    if (s.source.mode === "live") return ["good", "live"];
    if (s.source.replay && s.source.replay.finished) return ["info", "replay finished"];
    if (s.source.mode === "replay") return ["good", "replaying"];
    if (s.source.run_status === "complete") return ["info", "finished"];
    if (s.source.run_status) return ["warn", "finished: " + s.source.run_status];
    return ["info", "watching folder"];
  }

  // Every request needs the token when one is set; the page got here with it, so a refusal now
  // means the monitor was restarted with another token.
  const refusal = (status) =>
    status === 401 ? (token ? "token required: the token in the address is wrong" : "token required: add ?token=… to the address") : "HTTP " + status;

  async function poll() {
    try {
      const r = await fetch(withToken("api/state"));
      if (r.ok) { const s = await r.json(); setConnection(...connectedBadge(s)); render(s); }
      else setConnection("bad", refusal(r.status));
    } catch (err) { setConnection("bad", "offline"); }
  }

  function connect() {
    const es = new EventSource(withToken("api/events"));
    es.addEventListener("state", (ev) => { const s = JSON.parse(ev.data); setConnection(...connectedBadge(s)); render(s); });
    // An event stream cannot tell why it failed: ask the server, so that a refused token reads
    // as such and not as a connection that keeps retrying.
    es.onerror = async () => {
      try {
        const r = await fetch(withToken("api/health"));
        if (r.status === 401) { es.close(); setConnection("bad", refusal(401)); return; }
        setConnection("bad", "reconnecting");
      } catch (err) { setConnection("bad", "offline, reconnecting"); }
    };
  }

  poll();
  connect();
  // The heartbeat age grows without new events: re-render the device panel every second.
  setInterval(() => { if (lastState) renderDevice(lastState); }, 1000);
})();
