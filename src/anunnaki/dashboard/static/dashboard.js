// Anunnaki dashboard: one snapshot, then patches over server-sent events; panes are redrawn
// in requestAnimationFrame, only those whose data changed. Plain JS, no build step, no CDN.
// Every text from the server goes through textContent (never innerHTML).
"use strict";

(function () {
  const SVGNS = "http://www.w3.org/2000/svg";
  const S = {               // what the page knows
    structure: null, goals: {}, analysis: {}, monitor: {}, values: {}, oracle: [],
    camera: {}, executions: [], decisions: [], timeline: [], now: 0, utu_t: null,
    latest_t: null, run: null, streaming: false,
    clock: "wall", t0: 0, operator: false, goal_source: "dashboard",
    assurance: null,        // the live case's statuses: {case, root, t, seq, claims, nodes}
  };
  let caseEls = null;       // GSN id -> {g, type, text}, once the drawing is in
  let caseLoading = false;
  let caseSelected = null;
  const dirty = new Set();   // panes to redraw
  const changedGoals = new Set();
  let nodeEls = {};          // goal id -> {g, u}
  let selected = null;
  let token = sessionStorage.getItem("anunnaki-token") || "";
  let lastTimelineDraw = 0;

  // -- helpers ------------------------------------------------------------------------------
  function $(id) { return document.getElementById(id); }
  function el(tag, attrs, ...kids) {
    const e = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs || {})) {
      if (v === null || v === undefined) continue;
      if (k === "class") e.className = v; else e.setAttribute(k, v);
    }
    for (const k of kids) e.append(k instanceof Node ? k : document.createTextNode(String(k)));
    return e;
  }
  function svg(tag, attrs) {
    const e = document.createElementNS(SVGNS, tag);
    for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
    return e;
  }
  function fmtU(u) { return u === null || u === undefined ? "?" : Number(u).toFixed(2); }
  function fmtT(t) {
    if (t === null || t === undefined) return "–";
    return (S.clock === "wall" ? t - S.t0 : t).toFixed(2);
  }
  function fmtV(v) {
    if (v === null || v === undefined) return "–";
    if (typeof v === "number") return Number.isInteger(v) ? String(v) : v.toFixed(3);
    if (typeof v === "object") return JSON.stringify(v);
    return String(v);
  }
  function fmtData(data) {
    return Object.entries(data || {}).filter(([, v]) => v !== null && v !== undefined)
      .map(([k, v]) => k + "=" + (typeof v === "object" ? JSON.stringify(v) : v)).join(" ");
  }
  function status(id) { const g = S.goals[id]; return g ? g[1] : "unknown"; }

  // -- state updates ------------------------------------------------------------------------
  function applySnapshot(s) {
    Object.assign(S, {
      structure: s.structure, goals: s.goals, analysis: s.analysis, values: s.values || {},
      oracle: s.oracle, camera: s.camera, executions: s.executions,
      decisions: s.decisions, timeline: s.timeline, now: s.now, utu_t: s.utu_t,
      latest_t: s.latest_t === undefined ? null : s.latest_t, run: s.run || null,
      clock: s.clock, t0: s.t0, operator: s.operator, goal_source: s.goal_source,
    });
    S.monitor = {};
    for (const row of s.monitor) S.monitor[row.topic] = row;
    buildTree();
    buildKnowledge();
    $("decision-log").tBodies[0].replaceChildren();
    addDecisionRows(S.decisions);
    ["header", "knowledge", "monitor", "oracle", "analyze", "plan", "execute", "camera",
     "timeline", "operator"].forEach((p) => dirty.add(p));
    for (const id of Object.keys(S.goals)) changedGoals.add(id);
    takeAssurance(s);
  }

  function applyPatch(p) {
    S.now = p.now;
    if (p.utu_t !== undefined) S.utu_t = p.utu_t;
    if (p.latest_t !== undefined) S.latest_t = p.latest_t;
    if (p.run !== undefined) S.run = p.run;
    dirty.add("header"); dirty.add("monitor");
    if (p.goals) {
      for (const [id, v] of Object.entries(p.goals)) { S.goals[id] = v; changedGoals.add(id); }
      if (p.goal_source) S.goal_source = p.goal_source;
    }
    if (p.analysis) { S.analysis = p.analysis; dirty.add("analyze"); dirty.add("plan"); dirty.add("header"); }
    if (p.monitor) { for (const row of p.monitor) S.monitor[row.topic] = row; }
    if (p.values) { S.values = p.values; dirty.add("knowledge"); }
    if (p.oracle) { S.oracle = p.oracle; dirty.add("oracle"); }
    if (p.camera) { S.camera = p.camera; dirty.add("camera"); }
    if (p.executions) { S.executions = p.executions; dirty.add("execute"); }
    if (p.decisions) {
      S.decisions = S.decisions.concat(p.decisions).slice(-2000);
      addDecisionRows(p.decisions);
      dirty.add("timeline");
    }
    if (p.timeline) { S.timeline = S.timeline.concat(p.timeline).slice(-5000); dirty.add("timeline"); }
    if (p.goals) dirty.add("timeline");
    takeAssurance(p);
  }

  // -- assurance case -----------------------------------------------------------------------
  // The drawing is the case's own SVG (made by the dashboard's process, fetched once and
  // parsed as XML: nothing in it runs); each claim's <g id="gsn-ID"> gets its live status as
  // a class, the stylesheet colours it, and its reason goes in its tooltip and, on a click,
  // in the pane's detail line. Statuses and reasons from the bus are text, never markup.
  function takeAssurance(p) {
    if (p.assurance !== undefined && p.assurance !== null) { S.assurance = p.assurance; dirty.add("case"); }
    if (p.assurance_drawing && !caseEls && !caseLoading) loadCaseDrawing();
  }
  async function loadCaseDrawing() {
    caseLoading = true;
    try {
      const r = await fetch("/api/assurance.svg");
      if (!r.ok) return;
      const doc = new DOMParser().parseFromString(await r.text(), "image/svg+xml");
      const root = doc.documentElement;
      if (root.nodeName !== "svg") return;
      root.querySelectorAll("script, foreignObject").forEach((n) => n.remove());
      const drawing = document.importNode(root, true);
      caseEls = {};
      drawing.querySelectorAll("g.gsn[id^='gsn-']").forEach((g) => {
        const id = g.id.slice(4);
        const title = g.querySelector("title");
        caseEls[id] = { g, type: g.classList[1] || "", text: title ? title.textContent : id, title };
        g.addEventListener("click", () => { caseSelected = id; drawCase(); });
      });
      $("case-drawing").replaceChildren(drawing);
      $("pane-case").hidden = false;
      dirty.add("case");
    } finally { caseLoading = false; }
  }
  function drawCase() {
    const a = S.assurance;
    if (!caseEls) return;
    if (a) {
      for (const [id, [st, reason]] of Object.entries(a.nodes)) {
        const e = caseEls[id];
        if (!e) continue;
        const cls = st.replace(/[^a-z]+/g, "-");
        e.g.setAttribute("class", `gsn ${e.type} ${cls}${id === caseSelected ? " selected" : ""}`);
        e.g.dataset.status = st;
        if (e.title) e.title.textContent = `${id} [${st}]${reason ? ": " + reason : ""} (${e.text})`;
      }
      const root = a.nodes[a.root];
      $("case-summary").textContent = `${a.case}: ${a.root} ${root ? root[0] : "?"}` +
        ` · active model ${a.active_model || "?"} · perceived ${a.perceived || "?"}` +
        (a.t === null || a.t === undefined ? "" : ` · t ${fmtT(a.t)}`);
      $("case-drawing").dataset.seq = a.seq === null || a.seq === undefined ? "" : String(a.seq);
    }
    if (caseSelected) {
      const e = caseEls[caseSelected];
      const [st, reason] = (a && a.nodes[caseSelected]) || ["", ""];
      $("case-detail").replaceChildren(el("p", { "data-node": caseSelected },
        el("strong", {}, caseSelected + " "), el("span", { class: "status" }, st || "–"),
        reason ? " — " + reason : "", el("br"), el("small", {}, e ? e.text : "")));
    }
  }

  // -- goal model -------------------------------------------------------------------------
  // Drawn as the paper's KAOS figures (Fig. 6, Fig. 18): goals refined top down; each
  // obstacle under the goal it obstructs, with a dashed red link up into that goal; a
  // resolution goal under the obstacle it resolves, with a link up into the obstacle (a
  // resolution goal that also refines another goal keeps its place there and gets the same
  // link); under each goal or obstacle, one white hexagon per agent responsible for it, linked
  // to it (an agent responsible for several goals appears under each, as in the paper). Every
  // node gets columns of its own, so nothing overlaps. Colours follow the analysis live:
  // goals and obstacles by their status; a hexagon and its responsibility link by how the
  // goal it hangs under stands (red: the agent does not achieve it; an obstacle that holds
  // counts as red); an obstruction link when the obstacle holds; a resolution link when the
  // resolution goal is satisfied.
  let linkEls = {};   // node id -> [[path element, kind]] links whose look follows its status
  let agentEls = {};  // goal or obstacle id -> [the hexagons of the agents responsible for it]
  let dutiesOf = {};  // agent id -> [goal or obstacle ids it is responsible for]
  let agentsOf = {};  // goal or obstacle id -> [agent ids responsible for it]
  let obstacleIds = new Set();
  const MIN_SCALE = 0.75;  // the smallest scale the goal model is drawn at
  const AGENT = "@";  // an agent's layout key is A1@G7: ids are identifiers, so never "@"

  // How well a node stands: a goal's status; an obstacle that holds is a failure.
  function health(id) {
    const st = status(id);
    if (!obstacleIds.has(id) || st === "unknown") return st;
    return st === "satisfied" ? "unsatisfied" : "satisfied";
  }
  function linkClass(kind, id) {
    if (kind === "responsibility") return "edge responsibility " + health(id);
    if (kind === "obstruct") return "edge obstruct" + (status(id) === "satisfied" ? " holds" : "");
    if (kind === "resolution") return "edge resolution" + (status(id) === "satisfied" ? " resolves" : "");
    return "edge refine";
  }

  function buildTree() {
    const st = S.structure;
    const root = $("goal-svg");
    root.replaceChildren();
    nodeEls = {}; linkEls = {}; agentEls = {}; dutiesOf = {}; agentsOf = {};
    if (!st) return;
    const goals = {}; st.goals.forEach((g) => { goals[g.id] = g; });
    const obstacles = {}; st.obstacles.forEach((o) => { obstacles[o.id] = o; });
    obstacleIds = new Set(Object.keys(obstacles));
    const agents = {}; (st.agents || []).forEach((a) => { agents[a.id] = a; });
    const obstaclesOf = {};
    st.obstacles.forEach((o) => o.obstructs.forEach((gid) => {
      (obstaclesOf[gid] = obstaclesOf[gid] || []).push(o.id);
    }));
    const refining = new Set([st.root]);
    st.goals.forEach((g) => g.children.forEach((c) => refining.add(c)));
    function duties(id, list) {
      const known = (list || []).filter((a) => agents[a]);
      agentsOf[id] = known;
      known.forEach((a) => (dutiesOf[a] = dutiesOf[a] || []).push(id));
      return known.map((a) => [a + AGENT + id, "agent"]);
    }
    // The children a node is laid out over: [key, kind] pairs.
    function kidsOf(key, kind) {
      if (kind === "goal") {
        const g = goals[key];
        return g.children.filter((c) => goals[c]).map((c) => [c, "goal"])
          .concat(duties(key, g.agents), (obstaclesOf[key] || []).map((o) => [o, "obstacle"]));
      }
      if (kind === "obstacle") {
        const o = obstacles[key];
        return o.resolutions.filter((r) => goals[r] && !refining.has(r)).map((r) => [r, "goal"])
          .concat(duties(key, o.agents || []));
      }
      return [];
    }
    const W = 74, H = 58, SIZE = { goal: [64, 34], obstacle: [64, 34], agent: [46, 24] };
    const pos = {}; let nextX = 0; let maxDepth = 0;
    function place(key, kind, depth) {
      const n = pos[key] = { x: 0, y: depth, kind };
      maxDepth = Math.max(maxDepth, depth);
      const xs = [];
      for (const [k, kk] of kidsOf(key, kind)) {
        if (!pos[k]) xs.push(place(k, kk, depth + 1));
        else if (kind === "goal" && kk === "goal") xs.push(pos[k].x);  // a shared child
      }
      n.x = xs.length ? (Math.min(...xs) + Math.max(...xs)) / 2 : nextX++;
      return n.x;
    }
    if (goals[st.root]) place(st.root, "goal", 0);
    st.goals.forEach((g) => { if (!pos[g.id]) place(g.id, "goal", 0); });
    st.obstacles.forEach((o) => { if (!pos[o.id]) place(o.id, "obstacle", 0); });
    const width = Math.max(nextX * W + 20, 300), height = (maxDepth + 1) * H + 16;
    root.setAttribute("width", width); root.setAttribute("height", height);
    root.setAttribute("viewBox", `0 0 ${width} ${height}`);
    // Shrunk to the pane's width (CSS max-width), never below 3/4 of its size: a model too
    // wide for that scrolls instead of turning unreadable. (CSSOM: allowed by the CSP.)
    root.style.minWidth = `${Math.round(width * MIN_SCALE)}px`;
    root.dataset.columns = String(nextX);
    function box(key) {
      const p = pos[key], [w, h] = SIZE[p.kind];
      return { x: 10 + p.x * W + (W - w) / 2, y: 10 + p.y * H, w, h };
    }
    // A link from a's edge to b's: down, up, or (same row) below both.
    function route(a, b) {
      const A = box(a), B = box(b);
      const ax = A.x + A.w / 2, bx = B.x + B.w / 2;
      let ay, by, c1, c2;
      if (B.y >= A.y + A.h) { ay = A.y + A.h; by = B.y; c1 = c2 = (ay + by) / 2; }
      else if (A.y >= B.y + B.h) { ay = A.y; by = B.y + B.h; c1 = c2 = (ay + by) / 2; }
      else { ay = A.y + A.h; by = B.y + B.h; c1 = ay + 22; c2 = by + 22; }
      return `M${ax},${ay} C${ax},${c1} ${bx},${c2} ${bx},${by}`;
    }
    const defs = svg("defs", {});
    ["obstruct", "resolution"].forEach((kind) => {
      const m = svg("marker", { id: "arrow-" + kind, class: kind, viewBox: "0 0 8 8", refX: "7", refY: "4", markerWidth: "7", markerHeight: "7", orient: "auto-start-reverse" });
      m.append(svg("path", { d: "M0,0 L8,4 L0,8 z" }));
      defs.append(m);
    });
    const edges = svg("g", { class: "edges" });
    // kind, from, to; the link's look follows node `follows`.
    function link(kind, from, to, follows, attrs) {
      if (!pos[from] || !pos[to]) return;
      const e = svg("path", Object.assign({ class: linkClass(kind, follows), d: route(from, to), "data-from": from.split(AGENT)[0], "data-to": to }, attrs || {}));
      if (kind === "obstruct" || kind === "resolution") e.setAttribute("marker-end", `url(#arrow-${kind})`);
      edges.append(e);
      if (kind !== "refine") (linkEls[follows] = linkEls[follows] || []).push([e, kind]);
    }
    st.goals.forEach((g) => g.children.forEach((c) => link("refine", g.id, c, g.id)));
    st.obstacles.forEach((o) => {
      o.obstructs.forEach((gid) => link("obstruct", o.id, gid, o.id));
      o.resolutions.forEach((gid) => link("resolution", gid, o.id, gid));
    });
    for (const [owner, list] of Object.entries(agentsOf)) {
      list.forEach((a) => link("responsibility", a + AGENT + owner, owner, owner, { "data-agent": a, "data-for": owner }));
    }
    root.append(defs, edges);
    const nodes = svg("g", { class: "nodes" });
    const descr = {}; st.goals.forEach((g) => { descr[g.id] = g.description; });
    st.obstacles.forEach((o) => { descr[o.id] = o.description; });
    for (const key of Object.keys(pos)) {
      const { x, y, w, h } = box(key), kind = pos[key].kind;
      if (kind === "agent") {
        const [aid, owner] = key.split(AGENT);
        const g = svg("g", { class: "agent " + health(owner), "data-agent": aid, "data-for": owner });
        g.append(svg("polygon", { points: `${x + 8},${y} ${x + w - 8},${y} ${x + w},${y + h / 2} ${x + w - 8},${y + h} ${x + 8},${y + h} ${x},${y + h / 2}` }));
        const t = svg("text", { x: x + w / 2, y: y + h / 2 + 4, class: "id" }); t.textContent = aid;
        const title = svg("title", {});
        title.textContent = `${aid}: ${agents[aid].description || ""} — responsible for ${(dutiesOf[aid] || []).join(", ")}`;
        g.append(title, t);
        nodes.append(g);
        (agentEls[owner] = agentEls[owner] || []).push(g);
        continue;
      }
      const obstacle = kind === "obstacle";
      const g = svg("g", { class: "node " + (obstacle ? "obstacle " : "") + status(key), "data-node": key, tabindex: "0" });
      if (obstacle) {
        g.append(svg("polygon", { points: `${x + 8},${y} ${x + w},${y} ${x + w - 8},${y + h} ${x},${y + h}` }));
      } else {
        g.append(svg("rect", { x, y, width: w, height: h, rx: 5 }));
      }
      const t1 = svg("text", { x: x + w / 2, y: y + 14, class: "id" }); t1.textContent = key;
      const t2 = svg("text", { x: x + w / 2, y: y + 27, class: "u" });
      const title = svg("title", {}); title.textContent = `${key}: ${descr[key] || ""}`;
      g.append(title, t1, t2);
      g.addEventListener("click", () => explain(key));
      g.addEventListener("keydown", (ev) => { if (ev.key === "Enter") explain(key); });
      nodes.append(g);
      nodeEls[key] = { g, u: t2, obstacle, status: null };
    }
    root.append(nodes);
  }

  function drawGoals() {
    for (const id of changedGoals) {
      const n = nodeEls[id]; if (!n) continue;
      const v = S.goals[id] || [null, "unknown"];
      const cls = "node " + (n.obstacle ? "obstacle " : "") + v[1] + (selected === id ? " selected" : "");
      if (n.g.getAttribute("class") !== cls) n.g.setAttribute("class", cls);
      const txt = "u " + fmtU(v[0]);
      if (n.u.textContent !== txt) n.u.textContent = txt;
      if (n.status === v[1]) continue;  // links and hexagons follow the status only
      n.status = v[1];
      for (const [e, kind] of linkEls[id] || []) e.setAttribute("class", linkClass(kind, id));
      const ac = "agent " + health(id);
      for (const g of agentEls[id] || []) g.setAttribute("class", ac);
    }
    for (const id of changedGoals) drawPill(id, S.goals[id] || [null, "unknown"]);
    changedGoals.clear();
    $("goal-source").textContent = S.goal_source === "utu" ? "as Utu evaluates it" : "evaluated by the dashboard (no analysis from Utu yet)";
  }

  async function explain(id) {
    if (selected && nodeEls[selected]) changedGoals.add(selected);
    selected = id; changedGoals.add(id);
    const box = $("explanation");
    try {
      const r = await fetch("/api/explain/" + encodeURIComponent(id));
      if (!r.ok) throw new Error((await r.json()).detail || r.statusText);
      const e = await r.json();
      const desc = (S.structure.goals.find((g) => g.id === id) || S.structure.obstacles.find((o) => o.id === id) || {}).description || "";
      const kids = [el("p", { class: "verdict" }, `${id} — ${desc}`)];
      if (e.utu) kids.push(el("p", {}, `Utu: ${e.utu.status} (utility ${fmtU(e.utu.utility)})`));
      const list = el("ul", { id: "explanation-text" });
      (function walk(x, depth) {
        const li = el("li", { "data-node": x.node }, x.summary);
        li.style.marginLeft = `${depth * 12}px`;  // CSSOM: allowed by the page's CSP
        list.append(li);
        x.because.forEach((b) => walk(b, depth + 1));
      })(e.explanation, 0);
      kids.push(list);
      const leaves = Object.entries(e.explanation.leaves || {});
      if (leaves.length) kids.push(el("p", { class: "sub" }, "values: " + leaves.map(([k, v]) => `${k} = ${fmtV(v)}`).join(", ")));
      box.replaceChildren(...kids);
      box.dataset.node = id;
    } catch (err) {
      box.replaceChildren(el("p", { class: "hint" }, `no explanation for ${id}: ${err.message}`));
    }
  }

  // -- panes --------------------------------------------------------------------------------
  function drawHeader() {
    // The latest time any pane shows (the server keeps it), so the header never lags them.
    $("utu-time").textContent = "t = " + fmtT(S.latest_t !== null ? S.latest_t : (S.utu_t !== null ? S.utu_t : S.now));
    drawConnection();
    const a = S.analysis || {};
    $("flag-paused").classList.toggle("hidden", !a.paused || a.run_stopped);
    $("flag-runstop").classList.toggle("hidden", !a.run_stopped);
    $("flag-warmup").classList.toggle("hidden", !a.warming_up);
    $("readonly").classList.toggle("hidden", S.operator);
    if (S.structure) { $("run-name").textContent = "· " + S.structure.name; document.title = "Anunnaki · " + S.structure.name; }
  }

  // The badge: "live" while the run is fed, "ended" once Utu's nodes are gone or nothing
  // has arrived for a while (the server decides: DashboardState.run), "reconnecting…" while
  // the page's own stream is down.
  function drawConnection() {
    const conn = $("connection");
    if (!S.streaming) { conn.textContent = "reconnecting…"; conn.className = "badge off"; conn.dataset.state = "reconnecting"; return; }
    const run = S.run || { live: true, state: "live", reason: null };
    conn.textContent = run.state === "live" ? "live" : run.state;
    conn.className = "badge " + (run.live ? "on" : "off");
    conn.dataset.state = run.state;
    conn.title = run.reason || "";
  }

  function drawOperator() {
    $("operator").classList.toggle("hidden", !S.operator);
    $("token").value = token;
  }

  // The knowledge pane is built once per snapshot; updates touch only what changed.
  let pillEls = {};   // goal id -> [pill elements]
  let attrEls = {};   // agent id -> attributes element
  function buildKnowledge() {
    const st = S.structure; pillEls = {}; attrEls = {};
    if (!st) { $("knowledge").replaceChildren(); return; }
    $("knowledge").replaceChildren(...st.agents.map((a) => {
      const goals = el("div", { class: "goals" });
      a.goals.forEach((gid) => {
        const pill = el("span", { class: "pill unknown", "data-goal": gid }, gid);
        (pillEls[gid] = pillEls[gid] || []).push(pill);
        goals.append(pill);
        changedGoals.add(gid);
      });
      attrEls[a.id] = el("div", { class: "attrs" }, "no values yet");
      return el("div", { class: "agent", "data-agent": a.id },
        el("span", { class: "aid" }, a.id), el("span", { class: "sub" }, a.description),
        attrEls[a.id], goals);
    }));
  }
  function drawPill(id, v) {
    for (const pill of (pillEls[id] || [])) {
      const cls = "pill " + v[1], txt = `${id} ${fmtU(v[0])}`;
      if (pill.className !== cls) pill.className = cls;
      if (pill.textContent !== txt) pill.textContent = txt;
    }
  }
  function drawKnowledge() {
    for (const [aid, box] of Object.entries(attrEls)) {
      const txt = Object.entries(S.values).filter(([k]) => k.startsWith(aid + ".") || k === `rate(${aid})`)
        .map(([k, v]) => `${k} = ${fmtV(v)}`).join("  ") || "no values yet";
      if (box.textContent !== txt) box.textContent = txt;
    }
  }

  // An age to the tenth, rounded up: a stale age (over its limit) never reads as the limit
  // itself (1.03 s past a 1.0 s limit shows 1.1 s, not "1.0 s" in red).
  function fmtAge(age) {
    return (Math.ceil(age * 10 - 1e-9) / 10).toFixed(1);
  }

  function drawMonitor() {
    const body = $("monitor").tBodies[0];
    const rows = Object.values(S.monitor).map((r) => {
      const age = r.last_t === null ? null : Math.max(0, S.now - r.last_t);
      const stale = age === null || age > r.staleness;
      return el("tr", { "data-topic": r.topic },
        el("td", {}, r.topic), el("td", {}, r.agents.join(", ")),
        el("td", { class: "value", title: JSON.stringify(r.last) }, r.last ? JSON.stringify(r.last) : "–"),
        el("td", { class: "num" }, r.rate === null ? "–" : r.rate.toFixed(1) + " Hz"),
        el("td", { class: "num age" + (stale ? " stale" : ""), title: `stale after ${r.staleness} s` },
          age === null ? "never" : fmtAge(age) + " s"),
        el("td", { class: "num limit" }, Number(r.staleness).toFixed(1) + " s"));
    });
    body.replaceChildren(...rows);
  }

  function drawOracle() {
    const box = $("oracle");
    if (!S.oracle.length) { box.replaceChildren(el("p", { class: "hint" }, "no assessment yet")); return; }
    box.replaceChildren(...S.oracle.map((o) => el("div", { class: "assessor", "data-assessor": o.assessor },
      el("div", { class: "category cat-" + o.category, title: "behavior category" }, String(o.category)),
      el("div", {}, el("b", {}, o.assessor), ` · confidence ${o.confidence === null ? "–" : o.confidence.toFixed(2)}`),
      el("div", { class: "sub" }, "context: " + (fmtData(o.context) || "–")),
      el("div", { class: "sub" }, `model ${o.model_id || "–"} · ${o.topic} · t ${fmtT(o.t)}`))));
  }

  function drawAnalyze() {
    const a = S.analysis || {};
    const descr = {}; (S.structure ? S.structure.goals : []).forEach((g) => { descr[g.id] = g.description; });
    $("violated").replaceChildren(...(a.violated || []).map((g) => el("li", { "data-goal": g, title: descr[g] || "" }, g)));
    $("eligible").replaceChildren(...(a.eligible || []).map((t) => el("li", { "data-tactic": t }, t)));
  }

  function drawPlan() {
    const q = (S.analysis && S.analysis.queue) || [];
    $("plan-empty").classList.toggle("hidden", q.length > 0);
    $("plan-queue").replaceChildren(...q.map((row) => {
      const li = el("li", { "data-tactic": row.tactic, class: row.state },
        el("b", {}, row.tactic), ` priority ${row.priority} `,
        el("span", { class: "state" }, row.state === "pending" ? "pending approval" : row.state));
      if (row.state === "pending" && S.operator) {
        const yes = el("button", { "data-op": "approve", "data-tactic": row.tactic }, "approve");
        const no = el("button", { "data-op": "reject", "data-tactic": row.tactic }, "reject");
        yes.addEventListener("click", () => operate("approve", { tactic: row.tactic }));
        no.addEventListener("click", () => operate("reject", { tactic: row.tactic }));
        li.append(yes, no);
      }
      return li;
    }));
  }

  const RESULT = {
    postcondition_ok: ["ok", "postconditions verified"],
    postcondition_failed: ["failed", "postconditions FAILED"],
    completed: ["ok", "completed (no postconditions)"],
    awaiting: ["awaiting", "awaiting postconditions"],
  };
  function drawExecute() {
    const ex = S.executions || [];
    $("execute-empty").classList.toggle("hidden", ex.length > 0);
    $("executions").replaceChildren(...ex.slice().reverse().slice(0, 30).map((e) => {
      const [cls, text] = RESULT[e.result] || ["", e.result];
      return el("li", { "data-tactic": e.tactic, "data-result": e.result },
        el("b", {}, e.tactic), ` started t=${fmtT(e.started)} `,
        el("span", { class: "result " + cls }, text + (e.result_t !== null ? ` at t=${fmtT(e.result_t)}` : "")),
        el("div", { class: "actions" }, e.actions.map((a) => `${a.type} ${a.ok ? "ok" : "FAILED"}`).join(" · ") || "–"));
    }));
  }

  // Frames drawn, measured on the frames' own stamps (publication, or simulated instant),
  // over the last FPS_WINDOW seconds of stamps: arrival bursts do not inflate the rate.
  const FPS_WINDOW = 2.0;
  let frameBusy = false, frameWanted = null, drawnStamps = [];
  function drawnFps(stamp) {
    if (typeof stamp !== "number") return null;
    if (drawnStamps.length && stamp < drawnStamps[drawnStamps.length - 1]) drawnStamps = [];
    drawnStamps.push(stamp);
    drawnStamps = drawnStamps.filter((t) => t >= stamp - FPS_WINDOW);
    const span = stamp - drawnStamps[0];
    return drawnStamps.length >= 2 && span > 0 ? (drawnStamps.length - 1) / span : null;
  }
  function drawCamera() {
    const c = S.camera || {};
    const act = c.active;
    $("camera-model").textContent = act && act.model ? `active model ${act.model} · domain ${act.domain || "default"}` : "no active model announced";
    if (c.frame) { frameWanted = { seq: c.frame.seq, t: c.frame.t }; fetchFrame(); }
  }
  async function fetchFrame() {
    if (frameBusy || frameWanted === null) return;
    const want = frameWanted; frameWanted = null; frameBusy = true;
    try {
      const r = await fetch("/api/frame/" + want.seq);
      if (r.ok) {
        const bmp = await createImageBitmap(await r.blob());
        paintFrame(bmp, want.seq, want.t);
      }
    } catch (err) { /* a frame that is gone is simply skipped */ }
    frameBusy = false;
    if (frameWanted !== null && frameWanted.seq !== want.seq) fetchFrame();
  }
  function paintFrame(bmp, seq, stamp) {
    const cv = $("camera"), ctx = cv.getContext("2d");
    if (cv.width !== bmp.width || cv.height !== bmp.height) { cv.width = bmp.width; cv.height = bmp.height; }
    ctx.drawImage(bmp, 0, 0);
    bmp.close();
    const d = (S.camera || {}).detections;
    let n = 0;
    if (d && d.boxes) {
      const sx = cv.width / (d.width || cv.width), sy = cv.height / (d.height || cv.height);
      ctx.lineWidth = Math.max(1, cv.width / 160);
      ctx.font = `${Math.max(9, cv.width / 24)}px sans-serif`;
      d.boxes.forEach((b, i) => {
        ctx.strokeStyle = "#31e27b"; ctx.fillStyle = "#31e27b";
        ctx.strokeRect(b[0] * sx, b[1] * sy, (b[2] - b[0]) * sx, (b[3] - b[1]) * sy);
        const label = `${(d.labels || [])[i] || ""} ${(((d.scores || [])[i]) || 0).toFixed(2)}`;
        ctx.fillText(label, b[0] * sx + 2, Math.max(10, b[1] * sy - 2));
        n++;
      });
    }
    cv.dataset.seq = String(seq); cv.dataset.boxes = String(n);
    const fps = drawnFps(stamp);
    cv.dataset.fps = fps === null ? "" : fps.toFixed(3);
    const f = (S.camera || {}).frame || {};
    $("camera-info").textContent = `frame ${seq} · ${f.width || bmp.width}×${f.height || bmp.height} · ${n} box${n === 1 ? "" : "es"} · ${fps === null ? "–" : fps.toFixed(1)} fps · ${S.camera.frames} frames`;
  }

  function drawTimeline() {
    const now = performance.now();
    if (now - lastTimelineDraw < 250) { dirty.add("timeline"); return; }
    lastTimelineDraw = now;
    const box = $("timeline");
    const w = box.clientWidth || 800, h = box.clientHeight || 150;
    box.setAttribute("viewBox", `0 0 ${w} ${h}`);
    const pts = S.timeline;
    const marks = S.decisions.filter((d) => MARK[d.kind] && d.t !== null);
    const ts = pts.map((p) => p.t).concat(marks.map((d) => d.t));
    if (S.utu_t !== null) ts.push(S.utu_t);
    const kids = [];
    const L = 34, R = 10, T = 16, B = 18;
    kids.push(svg("line", { class: "axis", x1: L, y1: h - B, x2: w - R, y2: h - B }));
    kids.push(svg("line", { class: "axis", x1: L, y1: T, x2: L, y2: h - B }));
    [0, 0.5, 1].forEach((u) => {
      const y = T + (1 - u) * (h - T - B);
      kids.push(svg("line", { class: "grid", x1: L, y1: y, x2: w - R, y2: y }));
      const tx = svg("text", { x: 4, y: y + 3 }); tx.textContent = u.toFixed(1); kids.push(tx);
    });
    if (ts.length) {
      let t0 = Math.min(...ts), t1 = Math.max(...ts);
      if (t1 - t0 < 1) t1 = t0 + 1;
      const X = (t) => L + (t - t0) / (t1 - t0) * (w - L - R);
      const Y = (u) => T + (1 - (u === null ? 0 : u)) * (h - T - B);
      // The first label starts at the axis's start, the last ends at its end: inside the plot.
      [[t0, "start"], [(t0 + t1) / 2, "middle"], [t1, "end"]].forEach(([t, anchor]) => {
        const tx = svg("text", { x: X(t), y: h - 4, "text-anchor": anchor, class: "tick" });
        tx.textContent = fmtT(t); kids.push(tx);
      });
      if (pts.length) {
        const step = Math.max(1, Math.floor(pts.length / 2000));
        let d = "";
        for (let i = 0; i < pts.length; i += step) {
          const p = pts[i];
          d += (d ? ` L${X(p.t).toFixed(1)},${Y(pts[Math.max(0, i - step)].u).toFixed(1)}` : `M${X(p.t).toFixed(1)},${Y(p.u).toFixed(1)}`);
          d += ` L${X(p.t).toFixed(1)},${Y(p.u).toFixed(1)}`;
        }
        const last = pts[pts.length - 1];
        d += ` L${X(t1).toFixed(1)},${Y(last.u).toFixed(1)}`;
        kids.push(svg("path", { class: "utility", d, "data-points": String(pts.length) }));
      }
      let labelRow = 0;
      marks.slice(-200).forEach((m) => {
        const cls = MARK[m.kind];
        const g = svg("g", { class: "marker " + cls + " " + m.kind, "data-kind": m.kind, "data-tactic": m.tactic || "", "data-t": String(m.t) });
        const x = X(m.t);
        g.append(svg("line", { x1: x, y1: T - 4, x2: x, y2: h - B }));
        const title = svg("title", {}); title.textContent = `t=${fmtT(m.t)} ${m.kind} ${m.tactic || ""} ${fmtData(m.data)}`;
        g.append(title);
        if (m.kind === "started" || m.kind === "run_stop" || m.kind === "escalated") {
          // Right of its line, or left of it near the plot's right end (never clipped).
          const right = x > w - R - 140;
          const tx = svg("text", { x: right ? x - 3 : x + 3, y: T + 8 + (labelRow++ % 3) * 11, "text-anchor": right ? "end" : "start" });
          tx.textContent = (m.tactic || m.kind) + (m.kind === "started" ? "" : " " + m.kind);
          g.append(tx);
        }
        kids.push(g);
      });
    }
    box.replaceChildren(...kids);
  }
  const MARK = {
    started: "started", postcondition_ok: "ok", completed: "ok", postcondition_failed: "failed",
    escalated: "failed", run_stop: "failed", paused: "operator", resumed_adaptation: "operator",
    approved: "operator", rejected: "operator",
  };

  function addDecisionRows(rows) {
    const body = $("decision-log").tBodies[0];
    const frag = document.createDocumentFragment();
    rows.slice(-300).reverse().forEach((d) => {
      frag.append(el("tr", { class: "k-" + d.kind, "data-kind": d.kind, "data-tactic": d.tactic || "" },
        el("td", { class: "num" }, fmtT(d.t)), el("td", { class: "kind" }, d.kind),
        el("td", {}, d.tactic || ""), el("td", { class: "detail" }, fmtData(d.data))));
    });
    body.prepend(frag);
    while (body.rows.length > 300) body.deleteRow(body.rows.length - 1);
  }

  // -- operator -----------------------------------------------------------------------------
  async function operate(op, body) {
    const out = $("operator-status");
    out.className = ""; out.textContent = op + "…";
    const headers = { "Content-Type": "application/json" };
    if (token) headers.Authorization = "Bearer " + token;
    try {
      const r = await fetch("/api/operator/" + op, { method: "POST", headers, body: JSON.stringify(body || {}) });
      const j = await r.json();
      if (!r.ok) { out.className = "bad"; out.textContent = `${op} refused: ${j.detail || r.status}`; return; }
      out.className = "ok"; out.textContent = `${op} sent as ${j.caller}`;
    } catch (err) {
      out.className = "bad"; out.textContent = `${op} failed: ${err.message}`;
    }
  }

  // -- the loop -----------------------------------------------------------------------------
  const DRAW = {
    header: drawHeader, operator: drawOperator, knowledge: drawKnowledge, monitor: drawMonitor,
    oracle: drawOracle, analyze: drawAnalyze, plan: drawPlan, execute: drawExecute,
    camera: drawCamera, timeline: drawTimeline, case: drawCase,
  };
  function frame() {
    if (changedGoals.size) drawGoals();
    if (dirty.size) {
      const todo = Array.from(dirty); dirty.clear();
      for (const p of todo) { try { DRAW[p](); } catch (err) { console.error(p, err); } }
    }
    requestAnimationFrame(frame);
  }

  function connect() {
    const es = new EventSource("/api/events");
    es.addEventListener("snapshot", (ev) => { S.streaming = true; applySnapshot(JSON.parse(ev.data)); });
    es.addEventListener("patch", (ev) => applyPatch(JSON.parse(ev.data)));
    es.onerror = () => { S.streaming = false; drawConnection(); };
  }

  document.addEventListener("DOMContentLoaded", () => {
    const m = /(?:^|[#&])token=([^&]+)/.exec(location.hash);
    if (m) {
      token = decodeURIComponent(m[1]);
      sessionStorage.setItem("anunnaki-token", token);
      history.replaceState(null, "", location.pathname + location.search);
    }
    $("token").addEventListener("change", (ev) => {
      token = ev.target.value.trim();
      sessionStorage.setItem("anunnaki-token", token);
    });
    document.querySelectorAll("#operator button[data-op]").forEach((b) => {
      b.addEventListener("click", () => {
        if (b.dataset.op === "run_stop" && !confirm("Run-stop: halt adaptation and stop the system?")) return;
        operate(b.dataset.op, {});
      });
    });
    const cv = $("camera"), ctx = cv.getContext("2d");
    ctx.fillStyle = "#9aa1ad"; ctx.font = "13px sans-serif";
    ctx.fillText("no camera frames yet", 16, 28);
    connect();
    requestAnimationFrame(frame);
  });
})();
