/* report.html: filter and sort the problem table, open a problem's drill-down, draw its pictures.
   Vanilla JavaScript, no network: the drawing data is the inline JSON #report-data
   (positions in mm, joint angles and path lengths in mrad; see suite/report/html/problems.py). */
(function () {
  "use strict";
  const DATA = JSON.parse(document.getElementById("report-data").textContent);
  const PLANNERS = DATA.planners;
  const COLORS = DATA.colors;
  const SVG = "http://www.w3.org/2000/svg";
  const byId = (id) => document.getElementById(id);

  document.querySelectorAll(".swatch[data-planner]").forEach((s) => {
    s.style.background = COLORS[s.dataset.planner] || "#777";
  });

  // ---- the problem table: filters ------------------------------------------------------------
  const table = byId("problem-table");
  if (!table) return;
  const tbody = table.tBodies[0];
  const rows = Array.from(tbody.rows);
  const filters = ["family", "kind", "planner", "status", "text"].reduce((o, k) => {
    o[k] = byId("f-" + k);
    return o;
  }, {});

  function statuses(row) {
    if (!row._st) {
      row._st = {};
      for (const tok of row.dataset.st.split(" ")) {
        const i = tok.lastIndexOf(":");
        const p = tok.slice(0, i);
        (row._st[p] = row._st[p] || []).push(tok.slice(i + 1));
      }
    }
    return row._st;
  }

  function matches(row) {
    if (filters.family.value && row.dataset.family !== filters.family.value) return false;
    if (filters.kind.value && row.dataset.kind !== filters.kind.value) return false;
    const text = filters.text.value.trim().toLowerCase();
    if (text && !row.dataset.pid.toLowerCase().startsWith(text)) return false;
    const want = filters.status.value;
    if (!want) return true;
    const ok = (s) => (want === "*failed" ? s !== "success" && s !== "none" : s === want);
    const st = statuses(row);
    const has = (p) => (st[p] || []).some(ok);
    const who = filters.planner.value;
    if (who === "*any") return PLANNERS.some(has);
    if (who === "*every") return PLANNERS.every(has);
    return has(who);
  }

  function applyFilters() {
    let shown = 0;
    for (const row of rows) {
      row.hidden = !matches(row);
      if (!row.hidden) shown += 1;
    }
    byId("f-count").textContent = "showing " + shown + " of " + rows.length + " problems";
  }
  Object.values(filters).forEach((el) => el.addEventListener("input", applyFilters));
  byId("f-reset").addEventListener("click", () => {
    filters.family.value = filters.kind.value = filters.status.value = filters.text.value = "";
    filters.planner.value = "*any";
    applyFilters();
  });

  // ---- sorting: click a header; again to reverse ------------------------------------------------
  Array.from(table.tHead.rows[0].cells).forEach((th, col) => {
    th.classList.add("sortable");
    th.addEventListener("click", () => {
      const asc = th.getAttribute("aria-sort") !== "ascending";
      Array.from(table.tHead.rows[0].cells).forEach((h) => h.removeAttribute("aria-sort"));
      th.setAttribute("aria-sort", asc ? "ascending" : "descending");
      const num = th.dataset.type === "num";
      const key = (row) => {
        const cell = row.cells[col];
        const v = cell.dataset.v !== undefined ? cell.dataset.v : cell.textContent;
        return num ? parseFloat(v) : v.toLowerCase();
      };
      const sorted = rows.slice().sort((a, b) => {
        const x = key(a), y = key(b);
        const c = x < y ? -1 : x > y ? 1 : 0;
        return asc ? c : -c;
      });
      sorted.forEach((r) => tbody.appendChild(r));
    });
  });

  // ---- drill-downs ------------------------------------------------------------------------------
  let current = null;

  function show(anchor) {
    const sec = byId(anchor);
    if (!sec || !sec.classList.contains("drill")) return;
    if (current && current !== sec) current.hidden = true;
    rows.forEach((r) => r.classList.toggle("selected", r.dataset.anchor === anchor));
    sec.hidden = false;
    current = sec;
    if (!sec.dataset.drawn) {
      drawViews(sec, DATA.problems[sec.dataset.pid]);
      drawJoints(sec, DATA.problems[sec.dataset.pid]);
      sec.dataset.drawn = "1";
    }
    sec.scrollIntoView({ block: "start" });
  }

  function close() {
    if (current) current.hidden = true;
    rows.forEach((r) => r.classList.remove("selected"));
    const row = current && rows.find((r) => r.dataset.anchor === current.id);
    current = null;
    history.replaceState(null, "", "#problems");
    if (row) row.scrollIntoView({ block: "center" });
  }

  function step(delta) {
    const shown = Array.from(tbody.rows).filter((r) => !r.hidden);
    if (!shown.length) return;
    const i = current ? shown.findIndex((r) => r.dataset.anchor === current.id) : -1;
    const next = shown[Math.min(shown.length - 1, Math.max(0, i < 0 ? 0 : i + delta))];
    location.hash = next.dataset.anchor;
  }

  tbody.addEventListener("click", (ev) => {
    const row = ev.target.closest("tr");
    if (!row || ev.target.closest("a")) return;
    location.hash = row.dataset.anchor;
  });
  window.addEventListener("hashchange", () => {
    const h = decodeURIComponent(location.hash.slice(1));
    if (h.startsWith("p-")) show(h);
  });
  byId("drills").addEventListener("click", (ev) => {
    const b = ev.target.closest("button[data-nav]");
    if (!b) return;
    const d = parseInt(b.dataset.nav, 10);
    if (d === 0) close();
    else step(d);
  });
  document.addEventListener("keydown", (ev) => {
    if (ev.target.closest("input, select, textarea") || ev.ctrlKey || ev.metaKey || ev.altKey) return;
    if (ev.key === "Escape" && current) close();
    else if (ev.key === "j") step(1);
    else if (ev.key === "k") step(-1);
  });

  // ---- drawing helpers --------------------------------------------------------------------------
  function el(tag, attrs, parent) {
    const e = document.createElementNS(SVG, tag);
    for (const k in attrs) e.setAttribute(k, attrs[k]);
    if (parent) parent.appendChild(e);
    return e;
  }

  function niceStep(span, ticks) {
    const raw = span / ticks;
    const p = Math.pow(10, Math.floor(Math.log10(raw)));
    for (const m of [1, 2, 2.5, 5, 10]) if (m * p >= raw) return m * p;
    return 10 * p;
  }

  function pairs(flat, stride, i, j) {
    const out = [];
    for (let k = 0; k + stride <= flat.length; k += stride) out.push([flat[k + i], flat[k + j]]);
    return out;
  }

  // ---- scene views: top (x, y) and side (y, z) ---------------------------------------------------
  const VIEWS = [
    { name: "top", title: "Top view", dims: [0, 1], axes: ["x (m)", "y (m)"] },
    { name: "side", title: "Side view, from +x", dims: [1, 2], axes: ["y (m)", "z (m)"] },
  ];

  function drawViews(sec, P) {
    const box = sec.querySelector(".views");
    const scene = P.scene ? DATA.scenes[P.scene] : null;
    const removed = new Set((P.removed || []).map(String));
    for (const v of VIEWS) {
      const shapes = [];
      if (scene) {
        for (const [kind, label, flat] of scene[v.name]) shapes.push({ kind, label, pts: pairs(flat, 2, 0, 1) });
        for (const id in scene.cans) {
          if (!removed.has(id)) shapes.push({ kind: "can", label: "can", pts: pairs(scene.cans[id][v.name], 2, 0, 1) });
        }
      }
      if (P.held) shapes.push({ kind: "held", label: "held can (at start)", pts: pairs(P.held[v.name], 2, 0, 1) });
      const lines = [];
      if (P.ref) lines.push({ name: "reference", ref: true, pts: pairs(P.ref.g, 3, v.dims[0], v.dims[1]) });
      for (const p of PLANNERS) {
        if (P.paths[p]) lines.push({ name: p, pts: pairs(P.paths[p].g, 3, v.dims[0], v.dims[1]) });
      }
      const marks = ["start", "goal"].filter((k) => P[k]).map((k) => ({ k, pt: [P[k][v.dims[0]], P[k][v.dims[1]]] }));
      const all = [].concat(...shapes.map((s) => s.pts), ...lines.map((l) => l.pts), marks.map((m) => m.pt));
      if (!all.length) continue;
      let [x0, x1, y0, y1] = [Infinity, -Infinity, Infinity, -Infinity];
      for (const [x, y] of all) {
        x0 = Math.min(x0, x); x1 = Math.max(x1, x); y0 = Math.min(y0, y); y1 = Math.max(y1, y);
      }
      const pad = 0.06 * Math.max(x1 - x0, y1 - y0, 100);
      const margin = { l: 0.12, b: 0.1 }; // room for tick labels, as a share of the span
      const w = x1 - x0 + 2 * pad, h = y1 - y0 + 2 * pad;
      const L = margin.l * Math.max(w, h), B = margin.b * Math.max(w, h);
      const fig = document.createElement("figure");
      fig.className = "view";
      const svg = el("svg", {
        viewBox: [x0 - pad - L, -(y1 + pad), w + L, h + B].join(" "),
        class: "scene", role: "img", "aria-label": v.title,
      }, fig);
      const fs = 0.032 * Math.max(w, h);
      // grid and ticks, labelled in metres
      const g = el("g", { class: "grid" }, svg);
      const s = niceStep(Math.max(w, h), 6);
      for (let x = Math.ceil((x0 - pad) / s) * s; x <= x1 + pad; x += s) {
        el("line", { x1: x, x2: x, y1: -(y0 - pad), y2: -(y1 + pad) }, g);
        el("text", { x, y: -(y0 - pad) + 1.1 * fs, "font-size": fs, "text-anchor": "middle" }, g).textContent = (x / 1000).toFixed(2);
      }
      for (let y = Math.ceil((y0 - pad) / s) * s; y <= y1 + pad; y += s) {
        el("line", { x1: x0 - pad, x2: x1 + pad, y1: -y, y2: -y }, g);
        el("text", { x: x0 - pad - 0.3 * fs, y: -y + 0.35 * fs, "font-size": fs, "text-anchor": "end" }, g).textContent = (y / 1000).toFixed(2);
      }
      el("text", { x: x1 + pad, y: -(y0 - pad) + 2.3 * fs, "font-size": fs, "text-anchor": "end", class: "axis" }, g).textContent = v.axes[0];
      el("text", { x: x0 - pad - L + 0.2 * fs, y: -(y1 + pad) + fs, "font-size": fs, class: "axis" }, g).textContent = v.axes[1];
      for (const sh of shapes) {
        const poly = el("polygon", { points: sh.pts.map(([x, y]) => x + "," + -y).join(" "), class: "k-" + sh.kind }, svg);
        el("title", {}, poly).textContent = sh.label;
      }
      for (const l of lines) {
        const pl = el("polyline", {
          points: l.pts.map(([x, y]) => x + "," + -y).join(" "),
          class: l.ref ? "path ref" : "path", stroke: l.ref ? "#555" : COLORS[l.name] || "#777",
        }, svg);
        el("title", {}, pl).textContent = l.name;
      }
      for (const m of marks) {
        const c = el("circle", { cx: m.pt[0], cy: -m.pt[1], r: 0.35 * fs, class: "mark " + m.k }, svg);
        el("title", {}, c).textContent = m.k + " (gripper)";
      }
      const cap = document.createElement("figcaption");
      cap.textContent = v.title;
      fig.appendChild(cap);
      box.appendChild(fig);
    }
    if (!box.children.length) {
      box.textContent = "Nothing to draw: no scene and no path.";
      return;
    }
    const legend = document.createElement("div");
    legend.className = "legend";
    const items = PLANNERS.map((p) => [P.paths[p] ? "line" : "none", COLORS[p], p + (P.paths[p] ? "" : " (no path)")]);
    if (P.ref) items.push(["ref", "#555", "reference (best known path)"]);
    items.push(["start", "", "start"], ["goal", "", "goal"]);
    if (!scene) items.push(["none", "", "scene not drawn (see the note above the table)"]);
    for (const [kind, color, text] of items) {
      const span = document.createElement("span");
      span.className = "item " + kind;
      const key = document.createElement("i");
      if (color) key.style.borderColor = color;
      span.appendChild(key);
      span.appendChild(document.createTextNode(text));
      legend.appendChild(span);
    }
    box.appendChild(legend);
  }

  // ---- joint paths over path length --------------------------------------------------------------
  function drawJoints(sec, P) {
    const box = sec.querySelector(".joints");
    const lines = [];
    if (P.ref) lines.push({ name: "reference", ref: true, d: P.ref });
    for (const p of PLANNERS) if (P.paths[p]) lines.push({ name: p, d: P.paths[p] });
    if (!lines.length) {
      box.textContent = "No planner found a path.";
      return;
    }
    const W = 300, H = 130, ml = 44, mr = 8, mt = 16, mb = 26;
    const sMax = Math.max(...lines.map((l) => l.d.s[l.d.s.length - 1]), 1);
    for (let j = 0; j < 7; j += 1) {
      let lo = Infinity, hi = -Infinity;
      for (const l of lines) for (let k = j; k < l.d.q.length; k += 7) { lo = Math.min(lo, l.d.q[k]); hi = Math.max(hi, l.d.q[k]); }
      const span = Math.max(hi - lo, 100);
      lo -= 0.1 * span; hi += 0.1 * span;
      const lim = [DATA.limits.lo[j], DATA.limits.hi[j]].filter((q) => q > lo - 0.3 * span && q < hi + 0.3 * span);
      for (const q of lim) { lo = Math.min(lo, q); hi = Math.max(hi, q); }
      const X = (s) => ml + (W - ml - mr) * s / sMax;
      const Y = (q) => mt + (H - mt - mb) * (hi - q) / (hi - lo);
      const svg = el("svg", { viewBox: "0 0 " + W + " " + H, class: "joint", role: "img", "aria-label": "joint " + (j + 1) });
      el("rect", { x: ml, y: mt, width: W - ml - mr, height: H - mt - mb, class: "frame" }, svg);
      el("text", { x: ml, y: 11, class: "title" }, svg).textContent = "joint " + (j + 1) + " (rad)";
      for (const q of [hi, lo]) {
        el("text", { x: ml - 4, y: Y(q) + 4, "text-anchor": "end" }, svg).textContent = (q / 1000).toFixed(2);
      }
      el("text", { x: ml, y: H - 8, "text-anchor": "start" }, svg).textContent = "0";
      el("text", { x: W - mr, y: H - 8, "text-anchor": "end" }, svg).textContent = (sMax / 1000).toFixed(2) + " rad of path";
      for (const q of lim) {
        const t = el("line", { x1: ml, x2: W - mr, y1: Y(q), y2: Y(q), class: "limit" }, svg);
        el("title", {}, t).textContent = "joint limit " + (q / 1000).toFixed(2) + " rad";
      }
      for (const l of lines) {
        const pts = l.d.s.map((s, k) => X(s).toFixed(1) + "," + Y(l.d.q[7 * k + j]).toFixed(1)).join(" ");
        const pl = el("polyline", { points: pts, class: l.ref ? "path ref" : "path", stroke: l.ref ? "#555" : COLORS[l.name] }, svg);
        el("title", {}, pl).textContent = l.name;
      }
      box.appendChild(svg);
    }
  }

  applyFilters();
  const start = decodeURIComponent(location.hash.slice(1));
  if (start.startsWith("p-")) show(start);
})();
