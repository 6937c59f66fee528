// nerve ui: the live graph of a robot, and the actions on it.
//
// The graph comes from /api/events (server-sent events, the router's graph
// every interval and after every action). Every action is a POST to
// /api/action with the token the page was opened with; the server carries
// it out through the router as the `nerve` command of the same name does,
// and a refusal comes back as the router's own message.
//
// Plain JavaScript and SVG, no library. window.nerveUi holds figures the
// tests and the benchmark read (updates received, time spent drawing).
'use strict';

const SVG = 'http://www.w3.org/2000/svg';
// The token comes in the address nerve ui printed (/?token=...). It is kept
// in sessionStorage (this tab only) and taken out of the address bar and
// the history; the page sends it in the X-Nerve-Token header. Opening the
// page with it also set an HttpOnly cookie, which the event stream and the
// images carry (they cannot send headers); actions need the header.
const params = new URLSearchParams(location.search);
const token = params.get('token') || sessionStorage.getItem('nerve-token') || '';
if (params.has('token')) {
  sessionStorage.setItem('nerve-token', token);
  history.replaceState(null, '', location.pathname);
}
const api = (path, opts = {}) => fetch(path, { ...opts, headers: { ...(opts.headers || {}), 'X-Nerve-Token': token } });
const NODE_W = 210, PORT_GAP = 18, HEAD_H = 58, COL_W = 360, ROW_GAP = 26;

const ui = window.nerveUi = { updates: 0, lastSeq: 0, drawMs: [], lastDrawMs: 0, editable: false, graph: null, errors: [], source: null, plotted: [] };
window.addEventListener('error', (e) => ui.errors.push(String(e.message)));
const pos = new Map();          // agent name -> {x, y, pinned}
const nodeEls = new Map();      // agent name -> {g, shape}
const edgeEls = new Map();      // "from->to" -> g
let selected = null;            // {kind: 'agent'|'edge', id}
let inspected = null;           // "agent/port" shown in the port panel
let drag = null;                // a connection or a node being dragged

const $ = (id) => document.getElementById(id);
function el(tag, attrs = {}, parent = null) {
  const e = document.createElementNS(SVG, tag);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  if (parent) parent.appendChild(e);
  return e;
}

// ---- messages ----------------------------------------------------------
let toastTimer = null;
function say(text, error = false) {
  const t = $('toast');
  t.textContent = text;
  t.className = error ? 'error' : '';
  t.hidden = false;
  clearTimeout(toastTimer);
  toastTimer = setTimeout(() => { t.hidden = true; }, error ? 8000 : 3000);
}

// ---- the server --------------------------------------------------------
async function act(action) {
  const r = await api('/api/action', {
    method: 'POST',
    headers: { 'Content-Type': 'application/json' },
    body: JSON.stringify(action),
  });
  const body = await r.json().catch(() => ({ error: `HTTP ${r.status}` }));
  if (!r.ok) { say(body.error || `HTTP ${r.status}`, true); throw new Error(body.error); }
  return body;
}

async function start() {
  const r = await api('/api/info');
  if (!r.ok) {
    const body = await r.json().catch(() => ({ error: `HTTP ${r.status}` }));
    $('mode').textContent = 'no access';
    $('mode').className = 'badge read-only';
    $('status').textContent = body.error || `HTTP ${r.status}`;
    $('status').className = 'badge down';
    return;
  }
  const info = await r.json();
  ui.editable = info.editable;
  document.body.classList.toggle('editable', info.editable);
  $('robot').textContent = info.robot;
  document.title = `nerve ui · ${info.robot}`;
  $('mode').textContent = info.read_only ? 'read-only' : (info.editable ? 'editing' : 'watching');
  $('mode').className = 'badge' + (info.editable ? '' : ' read-only');
  if (info.editable) {
    const kinds = await (await api('/api/kinds')).json();
    for (const k of kinds) { const o = document.createElement('option'); o.textContent = k; $('add-kind').appendChild(o); }
  }
  const es = ui.source = new EventSource('/api/events');
  es.onmessage = (m) => update(JSON.parse(m.data));
  es.onerror = () => { $('status').textContent = 'nerve ui unreachable'; $('status').className = 'badge down'; };
}

// ---- drawing -----------------------------------------------------------
function update(snap) {
  const t0 = performance.now();
  ui.updates += 1;
  ui.lastSeq = snap.seq;
  $('updated').textContent = `updated ${new Date(snap.unix_ms).toLocaleTimeString()}`;
  if (snap.error) {
    $('status').textContent = snap.error;
    $('status').className = 'badge down';
    return;
  }
  $('status').textContent = `${snap.graph.agents.length} agents · ${snap.graph.connections.length} connections`;
  $('status').className = 'badge';
  draw(snap.graph);
  const ms = performance.now() - t0;
  ui.lastDrawMs = ms;
  ui.drawMs.push(ms);
  if (ui.drawMs.length > 200) ui.drawMs.shift();
}

// An agent's ports as the page draws them: a client (it calls a service)
// on the left among the inputs, a service it answers on the right among the
// outputs, since the router wires a service to a client as a connection.
function ins(a) { return a.inputs.concat((a.clients || []).map((p) => ({ ...p, call: 'client' }))); }
function outs(a) { return a.outputs.concat((a.services || []).map((p) => ({ ...p, call: 'service' }))); }

function nodeHeight(a) { return HEAD_H + PORT_GAP * Math.max(ins(a).length, outs(a).length, 1); }

// Sources on the left, actuators (agents without outputs) on the right,
// every other agent one column right of its furthest source.
function layout(g) {
  const col = new Map(g.agents.map((a) => [a.name, 0]));
  const agentOf = (p) => p.split('/')[0];
  for (let i = 0; i < g.agents.length; i++) {
    let moved = false;
    for (const c of g.connections) {
      const f = agentOf(c.from), t = agentOf(c.to);
      if (f === t || !col.has(f) || !col.has(t)) continue;
      if (col.get(t) < col.get(f) + 1 && col.get(f) + 1 <= g.agents.length) { col.set(t, col.get(f) + 1); moved = true; }
    }
    if (!moved) break;
  }
  const last = Math.max(0, ...col.values());
  for (const a of g.agents) if (outs(a).length === 0 && ins(a).length > 0) col.set(a.name, Math.max(last, 1));
  const y = new Map();
  const sorted = [...g.agents].sort((a, b) => a.name.localeCompare(b.name));
  for (const a of sorted) {
    const c = col.get(a.name);
    const top = y.get(c) || 20;
    const p = pos.get(a.name);
    if (!p || !p.pinned) pos.set(a.name, { x: 20 + c * COL_W, y: top, pinned: false });
    y.set(c, top + nodeHeight(a) + ROW_GAP);
  }
}

function portXY(ref, dir) {
  const [agent, port] = ref.split('/');
  const a = ui.graph && ui.graph.agents.find((x) => x.name === agent);
  const p = pos.get(agent);
  if (!a || !p) return null;
  const list = dir === 'in' ? ins(a) : outs(a);
  const i = list.findIndex((x) => x.name === port);
  if (i < 0) return null;
  return { x: p.x + (dir === 'in' ? 0 : NODE_W), y: p.y + HEAD_H + PORT_GAP * i + PORT_GAP / 2 };
}

function fmtPeriod(ns) {
  if (ns == null) return '';
  return ns >= 1e9 ? `${ns / 1e9}s` : ns >= 1e6 ? `${+(ns / 1e6).toFixed(3)}ms` : `${+(ns / 1e3).toFixed(1)}µs`;
}
function isPeriodic(a) { return String(a.task).toLowerCase() === 'periodic'; }
function stateOf(a) { return String(a.state).toLowerCase(); }

function drawNode(a) {
  const shape = JSON.stringify([ins(a), outs(a)]);
  let n = nodeEls.get(a.name);
  if (!n || n.shape !== shape) {
    if (n) n.g.remove();
    const g = el('g', { class: 'node', 'data-agent': a.name }, $('nodes'));
    el('rect', { class: 'body', width: NODE_W, height: nodeHeight(a) }, g);
    const name = el('text', { class: 'name', x: 10, y: 17 }, g);
    name.textContent = a.name;
    el('text', { class: 'state', x: NODE_W - 8, y: 16, 'text-anchor': 'end' }, g);
    el('text', { class: 'info kind', x: 10, y: 32 }, g);
    el('text', { class: 'info figures', x: 10, y: 46 }, g);
    ins(a).forEach((p, i) => drawPort(g, a, p, 'in', i));
    outs(a).forEach((p, i) => drawPort(g, a, p, 'out', i));
    name.addEventListener('pointerdown', (ev) => startNodeDrag(ev, a.name));
    g.querySelector('rect.body').addEventListener('pointerdown', (ev) => startNodeDrag(ev, a.name));
    n = { g, shape, state: g.querySelector('text.state'), kind: g.querySelector('text.kind'), figures: g.querySelector('text.figures') };
    nodeEls.set(a.name, n);
  }
  const p = pos.get(a.name);
  n.g.setAttribute('transform', `translate(${p.x},${p.y})`);
  n.g.setAttribute('class', `node ${stateOf(a)}` + (selected && selected.kind === 'agent' && selected.id === a.name ? ' selected' : ''));
  n.state.textContent = stateOf(a);
  n.kind.textContent =
    `${a.kind} · ${isPeriodic(a) ? 'every ' + fmtPeriod(a.period_ns) : 'event-driven'}`;
  const s = a.stats;
  const figs = s ? `${s.rate_hz.toFixed(1)} Hz · CPU ${s.cpu_percent.toFixed(1)}%` : 'no figures';
  n.figures.textContent = `${figs} · restarts ${a.restarts || 0}`;
}

function drawPort(g, a, p, dir, i) {
  const x = dir === 'in' ? 0 : NODE_W, y = HEAD_H + PORT_GAP * i + PORT_GAP / 2;
  const ref = `${a.name}/${p.name}`;
  const pg = el('g', { class: `port ${dir}` + (p.call ? ` call ${p.call}` : ''), 'data-port': ref, 'data-dir': dir, 'data-type': p.type_name }, g);
  el('circle', { cx: x, cy: y, r: 6 }, pg);
  const label = el('text', { x: dir === 'in' ? 10 : NODE_W - 10, y: y + 3, 'text-anchor': dir === 'in' ? 'start' : 'end' }, pg);
  label.textContent = p.name;
  const type = el('tspan', { class: 'type', dx: 4 }, label);
  type.textContent = p.type_name.replace(/^nerve::/, '');
  pg.addEventListener('pointerdown', (ev) => startPortDrag(ev, ref, dir, p.type_name));
}

function edgePath(a, b) {
  const dx = Math.max(40, Math.abs(b.x - a.x) / 2);
  return `M ${a.x} ${a.y} C ${a.x + dx} ${a.y}, ${b.x - dx} ${b.y}, ${b.x} ${b.y}`;
}

function drawEdges(g) {
  const seen = new Set();
  for (const c of g.connections) {
    const key = `${c.from}->${c.to}`;
    seen.add(key);
    const a = portXY(c.from, 'out'), b = portXY(c.to, 'in');
    let e = edgeEls.get(key);
    if (!e) {
      e = el('g', { class: 'edge', 'data-from': c.from, 'data-to': c.to }, $('edges'));
      el('path', { class: 'line', 'marker-end': 'url(#arrow)' }, e);
      el('path', { class: 'hit' }, e).addEventListener('click', () => select({ kind: 'edge', id: key }));
      // the label lies above the nodes, in a layer of its own
      e.label = el('text', { 'text-anchor': 'middle', class: 'edge-label', 'data-from': c.from, 'data-to': c.to }, $('labels'));
      e.line = e.querySelector('path.line'); e.hit = e.querySelector('path.hit');
      edgeEls.set(key, e);
    }
    e.style.display = e.label.style.display = a && b ? '' : 'none';
    if (!a || !b) continue;
    const d = edgePath(a, b);
    e.line.setAttribute('d', d);
    e.hit.setAttribute('d', d);
    const label = e.label;
    label.setAttribute('x', (a.x + b.x) / 2);
    label.setAttribute('y', (a.y + b.y) / 2 - 6);
    const age = c.last_age_ms == null ? '–' : `${c.last_age_ms < 10 ? c.last_age_ms.toFixed(1) : Math.round(c.last_age_ms)} ms`;
    label.textContent = `${c.rate_hz.toFixed(1)} Hz · ${age} · ${c.dropped} lost`;
    e.setAttribute('class', 'edge' + (c.active ? '' : ' inactive') + (c.dropped > 0 ? ' lossy' : '') +
      (selected && selected.kind === 'edge' && selected.id === key ? ' selected' : ''));
  }
  for (const [k, e] of edgeEls) if (!seen.has(k)) { e.remove(); e.label.remove(); edgeEls.delete(k); }
}

function draw(g) {
  ui.graph = g;
  layout(g);
  const names = new Set(g.agents.map((a) => a.name));
  for (const [name, n] of nodeEls) if (!names.has(name)) { n.g.remove(); nodeEls.delete(name); pos.delete(name); }
  for (const a of g.agents) drawNode(a);
  drawEdges(g);
  // one unit one pixel while the graph fits; scaled down to fit when it does not
  const box = $('viewport').getBBox(), svg = $('graph');
  const w = Math.max(box.x + box.width + 40, svg.clientWidth), h = Math.max(box.y + box.height + 40, svg.clientHeight);
  svg.setAttribute('viewBox', `0 0 ${w} ${h}`);
  showSelection();
}

// ---- dragging ----------------------------------------------------------
function svgPoint(ev) {
  const svg = $('graph');
  const pt = svg.createSVGPoint();
  pt.x = ev.clientX; pt.y = ev.clientY;
  return pt.matrixTransform(svg.getScreenCTM().inverse());
}

function startNodeDrag(ev, name) {
  ev.stopPropagation();
  const p = svgPoint(ev), at = pos.get(name);
  drag = { node: name, dx: p.x - at.x, dy: p.y - at.y, moved: false };
}

function startPortDrag(ev, ref, dir, type) {
  ev.stopPropagation();
  if (dir !== 'out' || !ui.editable) { drag = { click: ref, dir }; return; }
  drag = { from: ref, type, moved: false, start: svgPoint(ev) };
  $('graph').classList.add('dragging');
  for (const p of document.querySelectorAll('.port.in')) {
    const fit = p.dataset.type === type;
    p.classList.toggle('fit', fit);
    p.classList.toggle('dim', !fit);
  }
}

document.addEventListener('pointermove', (ev) => {
  if (!drag) return;
  const p = svgPoint(ev);
  if (drag.node) {
    drag.moved = true;
    pos.set(drag.node, { x: p.x - drag.dx, y: p.y - drag.dy, pinned: true });
    if (ui.graph) { for (const a of ui.graph.agents) if (a.name === drag.node) drawNode(a); drawEdges(ui.graph); }
  } else if (drag.from) {
    if (Math.hypot(p.x - drag.start.x, p.y - drag.start.y) > 3) drag.moved = true;
    const a = portXY(drag.from, 'out');
    if (a) $('drag-line').setAttribute('d', edgePath(a, p));
  }
});

document.addEventListener('pointerup', (ev) => {
  const d = drag;
  drag = null;
  $('graph').classList.remove('dragging');
  $('drag-line').setAttribute('d', '');
  if (!d) return;
  if (d.node) { if (!d.moved) select({ kind: 'agent', id: d.node }); return; }
  const target = document.elementFromPoint(ev.clientX, ev.clientY);
  const port = target && target.closest && target.closest('.port');
  if (d.click) { inspect(d.click, d.dir); return; }
  if (!d.moved || !port || port.dataset.port === d.from) { inspect(d.from, 'out'); return; }
  if (port.dataset.dir !== 'in') { say('drop the connection on an input port (left side of an agent)', true); return; }
  const to = port.dataset.port;
  act({ op: 'connect', from: d.from, to }).then(() => say(`connected ${d.from} -> ${to}`)).catch(() => {});
});

document.addEventListener('keydown', (ev) => {
  if ((ev.key === 'Delete' || ev.key === 'Backspace') && selected && selected.kind === 'edge' && ui.editable &&
      !['INPUT', 'SELECT'].includes(document.activeElement.tagName)) {
    disconnectSelected();
  }
});

function disconnectSelected() {
  const [from, to] = selected.id.split('->');
  act({ op: 'disconnect', from, to }).then(() => { say(`disconnected ${from} -> ${to}`); select(null); }).catch(() => {});
}

// ---- the side panel ----------------------------------------------------
function facts(table, rows) {
  table.replaceChildren();
  for (const [k, v] of rows) {
    const tr = table.insertRow();
    tr.insertCell().textContent = k;
    tr.insertCell().textContent = v;
  }
}

function select(what) {
  selected = what;
  if (what && what.kind === 'agent') { $('params').replaceChildren(); $('agent-period').value = ''; }
  if (ui.graph) draw(ui.graph);
  showSelection();
}

function showSelection() {
  const g = ui.graph;
  const agent = g && selected && selected.kind === 'agent' && g.agents.find((a) => a.name === selected.id);
  const edge = g && selected && selected.kind === 'edge' && g.connections.find((c) => `${c.from}->${c.to}` === selected.id);
  $('agent-panel').hidden = !agent;
  $('edge-panel').hidden = !edge;
  if (agent) {
    $('agent-title').textContent = agent.name;
    const s = agent.stats;
    facts($('agent-facts'), [
      ['kind', agent.kind], ['state', stateOf(agent)], ['pid', agent.pid],
      ['task', isPeriodic(agent) ? `periodic, every ${fmtPeriod(agent.period_ns)}` : 'event-driven'],
      ['rate', s ? `${s.rate_hz.toFixed(2)} Hz` : '–'], ['CPU', s ? `${s.cpu_percent.toFixed(1)} %` : '–'],
      ['memory', s ? `${(s.rss_bytes / 1048576).toFixed(1)} MiB` : '–'],
      ['cycles', s ? s.cycles : '–'], ['overruns', s ? s.overruns : '–'],
      ['restarts', agent.restarts || 0], ['log', agent.log_file || '–'],
    ]);
  }
  if (edge) {
    $('edge-title').textContent = `${edge.from} → ${edge.to}`;
    facts($('edge-facts'), [
      ['type', edge.type_name], ['active', edge.active ? 'yes' : 'no'], ['rate', `${edge.rate_hz.toFixed(2)} Hz`],
      ['last sample', edge.last_age_ms == null ? '–' : `${edge.last_age_ms.toFixed(1)} ms ago`],
      ['received', edge.received], ['lost', edge.dropped],
    ]);
  }
}

for (const b of document.querySelectorAll('#agent-panel [data-action]')) {
  b.addEventListener('click', () => {
    if (!selected || selected.kind !== 'agent') return;
    const name = selected.id, op = b.dataset.action;
    const action = op === 'rate' ? { op, name, period: $('agent-period').value.trim() } : { op, name };
    act(action).then(() => say(`${name}: ${op} done`)).catch(() => {});
  });
}
document.querySelector('#edge-panel [data-action=disconnect]').addEventListener('click', disconnectSelected);
$('add-go').addEventListener('click', () => {
  const kind = $('add-kind').value, name = $('add-name').value.trim();
  if (!name) { say('give the new agent a name', true); return; }
  say(`starting ${name} (${kind})…`);
  act({ op: 'start', kind, name }).then(() => say(`${name} started`)).catch(() => {});
});

$('params-load').addEventListener('click', loadParams);
async function loadParams() {
  if (!selected || selected.kind !== 'agent') return;
  const name = selected.id;
  const list = await act({ op: 'params', name }).catch(() => null);
  const table = $('params');
  table.replaceChildren();
  if (!list) return;
  if (list.length === 0) { table.insertRow().insertCell().textContent = 'no parameters'; return; }
  for (const p of list) {
    const tr = table.insertRow();
    tr.insertCell().textContent = p.key;
    const cell = tr.insertCell();
    if (ui.editable && !p.read_only) {
      const input = document.createElement('input');
      input.value = p.value; input.size = 8; input.dataset.param = p.key;
      const set = document.createElement('button');
      set.textContent = 'set'; set.className = 'small';
      set.addEventListener('click', () => act({ op: 'param_set', name, key: input.dataset.param, value: input.value })
        .then(() => say(`${name}: ${input.dataset.param} = ${input.value}`)).catch(() => {}));
      cell.append(input, ' ', set);
    } else {
      cell.textContent = p.value;
    }
  }
}

// ---- looking inside a port ---------------------------------------------
let inspectTimer = null, inspectAfter = 0, series = [];
function inspect(ref, dir) {
  if (dir === 'in') {
    const sources = (ui.graph ? ui.graph.connections : []).filter((c) => c.to === ref).map((c) => c.from);
    if (sources.length === 0) { say(`${ref} is connected to nothing`); return; }
    ref = sources[0];
  }
  inspected = ref; inspectAfter = 0; ui.plotted = series = [];
  for (const p of document.querySelectorAll('.port.inspected')) p.classList.remove('inspected');
  const p = document.querySelector(`.port[data-port="${CSS.escape(ref)}"]`);
  if (p) p.classList.add('inspected');
  $('port-panel').hidden = false;
  $('port-title').textContent = ref;
  $('plot-field').replaceChildren();
  $('items').hidden = $('items-note').hidden = true;
  clearInterval(inspectTimer);
  inspectTimer = setInterval(poll, 300);
  poll();
}

function flatten(v, path = '', out = []) {
  if (v !== null && typeof v === 'object') {
    for (const [k, x] of Object.entries(v)) flatten(x, path ? `${path}.${k}` : k, out);
  } else {
    out.push([path, v]);
  }
  return out;
}

// The number at a plot path of a sample: `pose.x`; in a sequence
// `header.frame`, `items[3].x` (none when the sample has fewer elements, or
// the element is past the rows sent) or `items[-1].x`, the last element's,
// as `nerve plot` takes them.
function valueAt(s, path) {
  const lookup = (v, p) => { const f = flatten(v).find(([k]) => k === p); return f && f[1]; };
  const m = /^items\[(-1|\d+)\]\.?(.*)$/.exec(path);
  if (s.len === undefined || !m) return lookup(s.value, path);
  const item = m[1] === '-1' ? s.last : (s.value.items || [])[+m[1]];
  return item == null ? undefined : lookup(item, m[2]);
}

// The fields a sample offers to plot (a sequence's element's in the order
// of `columns`).
function plotPaths(s, columns) {
  const numbers = (v, prefix) => flatten(v).filter(([, x]) => typeof x === 'number').map(([k]) => prefix(k));
  if (s.len === undefined) return numbers(s.value, (k) => k);
  const element = s.last == null ? [] : (columns || []).filter((k) => typeof valueAt(s, `items[-1].${k}`) === 'number' ||
    (k === '' && typeof s.last === 'number'));
  return [...numbers(s.value.header, (k) => `header${k ? '.' + k : ''}`),
    ...element.map((k) => `items[-1]${k ? '.' + k : ''}`), ...element.map((k) => `items[0]${k ? '.' + k : ''}`)];
}

const fmt = (v) => (typeof v === 'number' ? +v.toPrecision(6) : v);
const MAX_COLUMNS = 20;

// A sequence's sample: its header's fields and length above, its elements
// as a table (the rows the server sent: the first `sequence.rows`), and
// how many more there are. A sample of no element is an empty table.
function showSequence(body, last) {
  facts($('sample'), [['sample #', last.seq], ['length', `${last.len} (longest seen ${body.sequence.longest})`],
    ...flatten(last.value.header).map(([k, v]) => [`header${k ? '.' + k : ''}`, fmt(v)])]);
  const rows = (last.value.items || []).map((r) => flatten(r));
  // the element's fields in declaration order, from its schema
  const itemColumns = (body.sequence.columns || []).slice(0, MAX_COLUMNS);
  const table = $('items');
  table.replaceChildren();
  const head = table.createTHead().insertRow();
  for (const k of ['#', ...itemColumns]) { const th = document.createElement('th'); th.textContent = k || 'value'; head.appendChild(th); }
  const tbody = table.createTBody();
  rows.forEach((r, i) => {
    const tr = tbody.insertRow();
    tr.insertCell().textContent = i;
    const at = new Map(r);
    for (const k of itemColumns) tr.insertCell().textContent = fmt(at.get(k));
  });
  const more = last.len - rows.length;
  $('items-note').textContent = last.len === 0 ? 'no elements in this sample'
    : more > 0 ? `elements 0-${rows.length - 1} of ${last.len}, and ${more} more` : `${last.len} elements`;
  table.hidden = false;
  $('items-note').hidden = false;
}

async function poll() {
  const ref = inspected;
  const r = await api(`/api/samples?port=${encodeURIComponent(ref)}&after=${inspectAfter}`);
  const body = await r.json().catch(() => ({ error: 'bad answer' }));
  if (ref !== inspected) return;
  if (!r.ok) { $('port-type').textContent = body.error; clearInterval(inspectTimer); return; }
  $('port-type').textContent = body.type_name;
  if (body.samples.length === 0) return;
  const last = body.samples[body.samples.length - 1];
  inspectAfter = last.seq;
  if (body.sequence && last.len !== undefined) {
    showSequence(body, last);
  } else {
    $('items').hidden = $('items-note').hidden = true;
    facts($('sample'), [['sample #', last.seq], ...flatten(last.value).map(([k, v]) => [k, fmt(v)])]);
  }
  // fields to plot: a sequence's element fields appear with its first non-empty sample
  const select = $('plot-field');
  const offered = new Set([...select.options].map((o) => o.textContent));
  for (const s of body.samples) {
    for (const k of plotPaths(s, body.sequence && body.sequence.columns)) {
      if (!offered.has(k)) { offered.add(k); const o = document.createElement('option'); o.textContent = k; select.appendChild(o); }
    }
  }
  for (const s of body.samples) {
    const v = valueAt(s, select.value);
    if (typeof v === 'number') series.push([s.stamp_ns / 1e9, v]);
  }
  if (series.length > 300) series = series.slice(-300);
  ui.plotted = series;
  plot();
  const img = $('port-image');
  img.hidden = !body.image;
  if (body.image) img.src = `/api/image?port=${encodeURIComponent(ref)}&seq=${last.seq}`;
}
$('plot-field').addEventListener('change', () => { ui.plotted = series = []; inspectAfter = 0; });

function plot() {
  const c = $('plot'), ctx = c.getContext('2d');
  ctx.clearRect(0, 0, c.width, c.height);
  if (series.length < 2) return;
  const xs = series.map((p) => p[0]), ys = series.map((p) => p[1]);
  const x0 = Math.min(...xs), x1 = Math.max(...xs), y0 = Math.min(...ys), y1 = Math.max(...ys);
  const sx = (x) => 30 + (c.width - 40) * (x - x0) / Math.max(x1 - x0, 1e-9);
  const sy = (y) => c.height - 14 - (c.height - 24) * (y - y0) / Math.max(y1 - y0, 1e-9);
  ctx.strokeStyle = '#2563eb'; ctx.lineWidth = 1.5; ctx.beginPath();
  series.forEach(([x, y], i) => (i ? ctx.lineTo(sx(x), sy(y)) : ctx.moveTo(sx(x), sy(y))));
  ctx.stroke();
  ctx.fillStyle = '#6b7580'; ctx.font = '10px sans-serif';
  ctx.fillText(String(+y1.toPrecision(4)), 2, 12);
  ctx.fillText(String(+y0.toPrecision(4)), 2, c.height - 16);
  ctx.fillText(`${(x1 - x0).toFixed(1)} s`, c.width - 40, c.height - 2);
}

start().catch((e) => say(`cannot start: ${e}`, true));
