// The live page of `bitrock watch --serve` and `bitrock serve`: the history first, then each
// window as the watch gives it (server-sent events from /events), drawn on canvases. No
// request leaves the server the page came from.
'use strict';

// Okabe & Ito's palette, for a law the watch's meta does not colour.
const PALETTE = ['#cc79a7', '#e69f00', '#009e73', '#56b4e9', '#000000', '#0072b2', '#d55e00', '#7f7f7f'];

const state = {
  meta: null,
  updates: [],
  view: null,
  ended: null,
  dropped: 0,
  // For each window received live: when its event arrived and when the page showed it
  // (ms since the epoch): what the browser test measures.
  timings: [],
  pending: [],
  // Each canvas's legend: rows and the right end of its widest row (CSS px).
  legends: {},
  // Whether a frame is due to draw what has arrived: the page shows what it holds once false.
  scheduled: false,
};
window.bitrockPage = state;

const $ = (id) => document.getElementById(id);

function lawNames() {
  if (state.meta && state.meta.laws) return state.meta.laws.map((l) => l.name);
  const last = state.updates.find((u) => u.laws.length > 0);
  return last ? last.laws.map((l) => l.law) : [];
}

// Each law's colour is the one of every figure and plot, sent with the watch's laws.
function color(law) {
  const spec = state.meta && state.meta.laws ? state.meta.laws.find((l) => l.name === law) : null;
  if (spec && spec.colour) return spec.colour;
  const k = lawNames().indexOf(law);
  return PALETTE[(k < 0 ? 0 : k) % PALETTE.length];
}

function fixed(v, digits) {
  return v === null || v === undefined || !Number.isFinite(v) ? '—' : v.toFixed(digits);
}

function short(v) {
  if (v === null || v === undefined || !Number.isFinite(v)) return '—';
  const a = Math.abs(v);
  if (a !== 0 && (a < 1e-3 || a >= 1e5)) return v.toExponential(2);
  return Number(v.toPrecision(4)).toString();
}

// ---- the stream ----

function connect() {
  const source = new EventSource('events');
  source.addEventListener('history', (e) => {
    const h = JSON.parse(e.data);
    state.meta = h.meta;
    state.updates = h.updates;
    state.view = h.view;
    state.ended = h.ended;
    setStatus(h.ended ? 'ended' : 'live');
    if (h.ended) source.close();
    schedule();
  });
  source.addEventListener('meta', (e) => {
    state.meta = JSON.parse(e.data);
    schedule();
  });
  source.addEventListener('update', (e) => {
    const u = JSON.parse(e.data);
    state.updates.push(u);
    state.pending.push({ window: u.window, received_ms: Date.now() });
    schedule();
  });
  source.addEventListener('view', (e) => {
    state.view = JSON.parse(e.data);
    schedule();
  });
  source.addEventListener('dropped', (e) => {
    state.dropped += JSON.parse(e.data).windows;
    schedule();
  });
  source.addEventListener('end', (e) => {
    state.ended = JSON.parse(e.data);
    setStatus('ended');
    source.close();
    schedule();
  });
  source.onerror = () => {
    if (!state.ended) setStatus('lost');
  };
  source.onopen = () => setStatus(state.ended ? 'ended' : 'live');
}

function setStatus(s) {
  const el = $('status');
  el.className = 'status ' + s;
  el.textContent = {
    live: 'live',
    ended: (state.ended && state.ended.said) || 'the watch has ended',
    lost: 'connection lost: reconnecting…',
  }[s];
}

function schedule() {
  if (state.scheduled) return;
  state.scheduled = true;
  requestAnimationFrame(() => {
    // A frame that fails to draw must not keep the page from drawing the next data.
    try {
      render();
    } finally {
      state.scheduled = false;
    }
    const shown = Date.now();
    for (const p of state.pending) state.timings.push({ window: p.window, received_ms: p.received_ms, shown_ms: shown });
    state.pending = [];
  });
}

// ---- the header and the tables ----

function render() {
  if (state.meta) {
    $('source').textContent = state.meta.source;
    $('criterion').textContent = `Under the mixture posterior, on ${state.meta.criterion}.`;
  }
  renderLawSelect();
  const u = state.updates[state.updates.length - 1];
  if (u) renderNow(u);
  renderLog();
  const note = $('note');
  note.hidden = state.dropped === 0;
  note.textContent = state.dropped
    ? `${state.dropped} windows were dropped for this page (it fell behind); reload it for the whole history.`
    : '';
  drawAlong($('along'));
  drawCloud($('cloud'));
  drawStrip($('strip'));
  drawMap($('map'));
  drawParams($('params'));
}

function renderNow(u) {
  $('window').textContent = String(u.window);
  $('time').textContent = `${fixed(u.start_s, 1)}–${fixed(u.end_s, 1)} s`;
  $('samples').textContent = `${u.samples_used} of ${u.samples}`;
  $('latency').textContent = `${fixed(u.latency_s, 2)} s`;
  $('most-probable').textContent = u.most_probable || '—';
  const title = u.most_probable ? titled(u.most_probable).slice(u.most_probable.length + 1) : '';
  $('most-probable-title').textContent = title;
  const answer = $('answer');
  answer.textContent = `this window's answer: ${u.answer ? u.answer.sentence : u.check ? `checked by re-simulation: ${u.check.verdict}` : '—'}`;
  const change = $('change');
  change.textContent = u.change ? `changed here (${fixed(u.change_nats, 0)} nats)` : u.uninformative ? 'this window informs nothing' : 'same';
  change.className = u.change ? 'changed' : '';
  const advice = $('advice');
  if (u.uninformative) {
    advice.textContent = `${u.uninformative}${u.advice ? '. Last advice: ' + u.advice.words : ''}`;
  } else {
    advice.textContent = u.advice ? u.advice.words : 'no advice yet';
  }
  const risk = state.meta && state.meta.risk;
  advice.className = 'advice' + (u.advice && risk ? (u.advice.p_unstable < risk ? ' safe' : ' risky') : '');
  const body = $('probabilities').tBodies[0];
  body.replaceChildren(
    ...u.laws.map((l) => {
      const tr = document.createElement('tr');
      tr.dataset.law = l.law;
      for (const [text, key] of [
        [titled(l.law), 'law'],
        [fixed(l.probability, 3), 'probability'],
        [fixed(l.window_probability, 3), 'window_probability'],
        [l.ln_z === null ? '— (ABC)' : `${fixed(l.ln_z, 1)} ± ${fixed(l.ln_z_error, 1)}`, 'ln_z'],
      ]) {
        const td = document.createElement('td');
        td.textContent = text;
        td.dataset.key = key;
        tr.append(td);
      }
      tr.cells[0].style.color = color(l.law);
      return tr;
    }),
  );
}

function renderLog() {
  const body = $('log').tBodies[0];
  // Newest first; rows already shown are kept (all redrawn after a reconnection to a shorter
  // history).
  if (state.updates.length < body.rows.length) body.replaceChildren();
  const shown = body.rows.length;
  for (const u of state.updates.slice(shown)) {
    const tr = document.createElement('tr');
    tr.dataset.window = u.window;
    const probabilities = u.laws.map((l) => `${l.law} ${fixed(l.probability, 3)}`).join(', ');
    for (const text of [
      String(u.window),
      fixed(u.end_s, 1),
      u.most_probable || '—',
      u.uninformative ? 'uninformative' : probabilities,
      u.change ? 'change' : '',
      u.advice ? u.advice.words : '',
    ]) {
      const td = document.createElement('td');
      td.textContent = text;
      tr.append(td);
    }
    if (u.change) tr.className = 'changed';
    body.prepend(tr);
  }
}

function renderLawSelect() {
  const select = $('law-select');
  const names = lawNames();
  if (select.options.length !== names.length) {
    select.replaceChildren(
      ...names.map((n) => {
        const o = document.createElement('option');
        o.value = n;
        o.textContent = titled(n);
        return o;
      }),
    );
    select.dataset.chosen = '';
  }
  // Follows the most probable law until the viewer picks one.
  const u = state.updates[state.updates.length - 1];
  if (!select.dataset.chosen && u && u.most_probable) select.value = u.most_probable;
}

// ---- drawing ----

// A canvas sized to its box on screen (device pixels), cleared: its context and CSS size.
function surface(canvas) {
  const ratio = window.devicePixelRatio || 1;
  const w = canvas.clientWidth || canvas.width;
  const h = canvas.clientHeight || canvas.height;
  canvas.width = Math.round(w * ratio);
  canvas.height = Math.round(h * ratio);
  const g = canvas.getContext('2d');
  g.setTransform(ratio, 0, 0, ratio, 0, 0);
  g.clearRect(0, 0, w, h);
  return { g, w, h };
}

// A plot area on a canvas: axes from `x` and `y` ([lo, hi]), labels, the legend `items`
// ([label, colour]) in as many rows above the plot as its width needs, and mapping functions.
function frame(canvas, x, y, xlabel, ylabel, items = []) {
  const { g, w, h } = surface(canvas);
  const rows = legend(g, canvas.id, 58, w - 12, items);
  const box = { left: 58, right: w - 12, top: 10 + LEGEND_ROW * rows, bottom: h - 38 };
  const px = (v) => box.left + ((v - x[0]) / (x[1] - x[0] || 1)) * (box.right - box.left);
  const py = (v) => box.bottom - ((v - y[0]) / (y[1] - y[0] || 1)) * (box.bottom - box.top);
  g.strokeStyle = '#9aa3ad';
  g.lineWidth = 1;
  g.strokeRect(box.left, box.top, box.right - box.left, box.bottom - box.top);
  g.fillStyle = '#5b6570';
  g.font = '11px system-ui, sans-serif';
  g.textAlign = 'center';
  for (const t of ticks(x[0], x[1], 6)) {
    g.fillText(short(t), px(t), box.bottom + 14);
  }
  g.fillText(xlabel, (box.left + box.right) / 2, box.bottom + 30);
  g.textAlign = 'right';
  for (const t of ticks(y[0], y[1], 5)) {
    g.fillText(short(t), box.left - 4, py(t) + 4);
  }
  g.save();
  g.translate(12, (box.top + box.bottom) / 2);
  g.rotate(-Math.PI / 2);
  g.textAlign = 'center';
  g.fillText(ylabel, 0, 0);
  g.restore();
  return { g, box, px, py };
}

function ticks(lo, hi, count) {
  if (!(hi > lo)) return [lo];
  const raw = (hi - lo) / count;
  const p = Math.pow(10, Math.floor(Math.log10(raw)));
  const step = [1, 2, 5, 10].map((m) => m * p).find((s) => s >= raw) || raw;
  const out = [];
  for (let t = Math.ceil(lo / step) * step; t <= hi + step * 1e-9; t += step) out.push(Math.abs(t) < step * 1e-9 ? 0 : t);
  return out;
}

function message(canvas, text) {
  const { g, box } = frame(canvas, [0, 1], [0, 1], '', '');
  g.fillStyle = '#5b6570';
  g.textAlign = 'center';
  g.fillText(text, (box.left + box.right) / 2, (box.top + box.bottom) / 2);
}

function extent(values) {
  let lo = Infinity;
  let hi = -Infinity;
  for (const v of values) {
    if (v === null || !Number.isFinite(v)) continue;
    if (v < lo) lo = v;
    if (v > hi) hi = v;
  }
  if (!(hi >= lo)) return [0, 1];
  if (hi === lo) return [lo - 1, hi + 1];
  const pad = (hi - lo) * 0.05;
  return [lo - pad, hi + pad];
}

// Height of a legend row, px.
const LEGEND_ROW = 16;

// The swatches and labels of `items` from the top of the canvas, between `left` and `right`,
// wrapped onto as many rows as they need; their extent is kept in `state.legends[id]` (what the
// browser test checks: nothing drawn past the canvas). Returns the rows used.
function legend(g, id, left, right, items) {
  g.font = '11px system-ui, sans-serif';
  g.textAlign = 'left';
  let x = left;
  let row = 0;
  let widest = left;
  for (const [label, c] of items) {
    const width = 13 + g.measureText(label).width;
    if (x > left && x + width > right) {
      row += 1;
      x = left;
    }
    const top = 4 + row * LEGEND_ROW;
    g.fillStyle = c;
    g.fillRect(x, top, 10, 10);
    g.strokeStyle = '#9aa3ad';
    g.lineWidth = 0.5;
    g.strokeRect(x, top, 10, 10);
    g.fillStyle = '#1b1f24';
    g.fillText(label, x + 13, top + 9);
    widest = Math.max(widest, x + width);
    x += width + 11;
  }
  const rows = items.length ? row + 1 : 0;
  state.legends[id] = { rows, right: widest, width: right + 12 };
  return rows;
}

// A law's name with whose law it is ("m2 Navarro-Lopez & Suarez"), where the meta says.
function titled(law) {
  const spec = state.meta && state.meta.laws ? state.meta.laws.find((l) => l.name === law) : null;
  return spec && spec.title ? `${law} ${spec.title}` : law;
}

// The path of the points (xs[k], ys[k]).
function polyline(g, px, py, xs, ys) {
  g.beginPath();
  xs.forEach((x, k) => (k === 0 ? g.moveTo(px(x), py(ys[k])) : g.lineTo(px(x), py(ys[k]))));
}

// Fills the area between `upper` and `lower` over `xs`.
function fillBetween(g, px, py, xs, upper, lower, fill, alpha) {
  polyline(g, px, py, xs, upper);
  for (let k = xs.length - 1; k >= 0; k--) g.lineTo(px(xs[k]), py(lower[k]));
  g.closePath();
  g.fillStyle = fill;
  g.globalAlpha = alpha;
  g.fill();
  g.globalAlpha = 1;
}

function changeLines(f, updates, y) {
  const { g, px, py } = f;
  g.save();
  g.strokeStyle = '#b3261e';
  g.setLineDash([5, 3]);
  g.lineWidth = 1.5;
  for (const u of updates) {
    if (!u.change) continue;
    g.beginPath();
    g.moveTo(px(u.start_s), py(y[0]));
    g.lineTo(px(u.start_s), py(y[1]));
    g.stroke();
  }
  g.restore();
}

function drawAlong(canvas) {
  const updates = state.updates;
  if (updates.length === 0) return message(canvas, 'no window yet');
  const x = [Math.min(...updates.map((u) => u.start_s)), Math.max(...updates.map((u) => u.end_s))];
  const names = lawNames();
  const items = names.map((n) => [titled(n), color(n)]).concat([['change', '#b3261e']]);
  const f = frame(canvas, x, [0, 1], 'end of the window along the record, s', 'P(law)', items);
  const { g, px, py, box } = f;
  // Uninformative windows: grey.
  g.fillStyle = '#e8eaed';
  for (const u of updates) {
    if (u.uninformative) g.fillRect(px(u.end_s) - 1, box.top, 2, box.bottom - box.top);
  }
  const informative = updates.filter((u) => !u.uninformative && u.laws.length > 0);
  let below = informative.map(() => 0);
  for (const name of names) {
    const above = informative.map((u, k) => below[k] + (u.laws.find((l) => l.law === name) || { probability: 0 }).probability);
    fillBetween(g, px, py, informative.map((u) => u.end_s), above, below, color(name), 0.8);
    below = above;
  }
  changeLines(f, updates, [0, 1]);
}

// True for a watch of surface channels: its windows carry no bit channels.
function surfaceWatch() {
  return Boolean(state.meta && state.meta.surface);
}

function drawCloud(canvas) {
  const v = state.view;
  if (!v) return message(canvas, 'no window yet');
  if (v.speed_rpm.length === 0 && (v.surface || surfaceWatch())) {
    return message(canvas, 'surface channels only: no bit speed or torque on bit to draw');
  }
  const band = v.band;
  const ys = v.torque.concat(band ? band.lower.concat(band.upper) : []);
  const xs = v.speed_rpm.concat(band ? band.speed_rpm : []);
  const items = band
    ? band.curves
        .map((c) => [`${c.law} MAP (P ${c.probability.toFixed(2)})`, color(c.law)])
        .concat([[`${Math.round(band.level * 100)} % band of the mixture`, 'rgba(31, 119, 180, 0.35)']])
    : [];
  const f = frame(canvas, extent(xs), extent(ys), `bit speed, rpm (window ${v.window})`, `torque, ${v.torque_unit}`, items);
  const { g, px, py } = f;
  if (band) {
    fillBetween(g, px, py, band.speed_rpm, band.upper, band.lower, 'rgb(31, 119, 180)', 0.18);
  }
  g.fillStyle = 'rgba(60, 60, 60, 0.45)';
  v.speed_rpm.forEach((s, k) => g.fillRect(px(s) - 1, py(v.torque[k]) - 1, 2, 2));
  if (band) {
    for (const c of band.curves) {
      polyline(g, px, py, band.speed_rpm, c.torque);
      g.strokeStyle = color(c.law);
      g.lineWidth = 1 + 3 * c.probability;
      g.stroke();
    }
  }
}

// P(stick-slip) as a colour: pale green at 0, deep red at 1.
// P(stick-slip) on the report's scale, sent with the watch's meta (one hue: no red against
// green).
function shade(p) {
  const stops = (state.meta && state.meta.probability_scale) || [[0, '#c8ccd1'], [1, '#5b6570']];
  const rgb = (hex) => [1, 3, 5].map((i) => parseInt(hex.slice(i, i + 2), 16));
  const q = Math.min(Math.max(p, 0), 1);
  let k = stops.findIndex((s) => s[0] >= q);
  if (k < 1) k = 1;
  const [p0, a] = [stops[k - 1][0], rgb(stops[k - 1][1])];
  const [p1, b] = [stops[k][0], rgb(stops[k][1])];
  const t = (q - p0) / (p1 - p0);
  const mix = (i) => Math.round(a[i] + (b[i] - a[i]) * t);
  return `rgb(${mix(0)}, ${mix(1)}, ${mix(2)})`;
}

function drawMap(canvas) {
  const v = state.view;
  const m = v && v.map;
  if (!m) return message(canvas, 'no posterior yet: the map comes with the first informative window');
  const nw = m.wob_kn.length;
  const dx = (m.omega_rpm[m.omega_rpm.length - 1] - m.omega_rpm[0]) / Math.max(m.omega_rpm.length - 1, 1);
  const dy = (m.wob_kn[nw - 1] - m.wob_kn[0]) / Math.max(nw - 1, 1);
  const x = [m.omega_rpm[0] - dx / 2, m.omega_rpm[m.omega_rpm.length - 1] + dx / 2];
  const y = [m.wob_kn[0] - dy / 2, m.wob_kn[nw - 1] + dy / 2];
  const u = state.updates.filter((u) => u.advice).pop();
  const items = [[`P = 0`, shade(0)], [`P = 1`, shade(1)], [`black line: P = ${m.risk}`, '#1b1f24']];
  if (u) {
    const a = u.advice;
    items.push([`now: ${a.omega_rpm.toFixed(0)} rpm, ${a.wob_kn.toFixed(0)} kN, P ${a.p_unstable.toFixed(2)}`, '#1b1f24']);
    if (a.safe_omega_rpm !== null || a.safe_wob_kn !== null) items.push(['advised', '#1b7f3b']);
  }
  const f = frame(canvas, x, y, 'top-drive speed, rpm', 'weight on bit, kN', items);
  const { g, px, py } = f;
  const p = (i, j) => m.p_unstable[i * nw + j];
  m.omega_rpm.forEach((o, i) => {
    m.wob_kn.forEach((w, j) => {
      const v = p(i, j);
      g.fillStyle = v === null ? '#c8ccd1' : shade(v);
      g.fillRect(px(o - dx / 2), py(w + dy / 2), px(o + dx / 2) - px(o - dx / 2) + 0.5, py(w - dy / 2) - py(w + dy / 2) + 0.5);
    });
  });
  // The risk's boundary: the cell edges between P below the risk and P at or above it.
  g.strokeStyle = '#1b1f24';
  g.lineWidth = 2;
  g.beginPath();
  const risky = (i, j) => p(i, j) !== null && p(i, j) >= m.risk;
  for (let i = 0; i < m.omega_rpm.length; i++) {
    for (let j = 0; j < nw; j++) {
      const o = m.omega_rpm[i];
      const w = m.wob_kn[j];
      if (i + 1 < m.omega_rpm.length && risky(i, j) !== risky(i + 1, j)) {
        g.moveTo(px(o + dx / 2), py(w - dy / 2));
        g.lineTo(px(o + dx / 2), py(w + dy / 2));
      }
      if (j + 1 < nw && risky(i, j) !== risky(i, j + 1)) {
        g.moveTo(px(o - dx / 2), py(w + dy / 2));
        g.lineTo(px(o + dx / 2), py(w + dy / 2));
      }
    }
  }
  g.stroke();
  if (u) {
    const a = u.advice;
    const mark = (o, w, fill, r) => {
      g.beginPath();
      g.arc(px(o), py(w), r, 0, 2 * Math.PI);
      g.fillStyle = fill;
      g.fill();
      g.strokeStyle = '#fff';
      g.lineWidth = 1.5;
      g.stroke();
    };
    for (const [o, w] of [
      [a.safe_omega_rpm, a.wob_kn],
      [a.omega_rpm, a.safe_wob_kn],
    ]) {
      if (o === null || w === null || (o === a.omega_rpm && w === a.wob_kn)) continue;
      g.strokeStyle = '#1b7f3b';
      g.lineWidth = 1.5;
      g.beginPath();
      g.moveTo(px(a.omega_rpm), py(a.wob_kn));
      g.lineTo(px(o), py(w));
      g.stroke();
      mark(o, w, '#1b7f3b', 5);
    }
    mark(a.omega_rpm, a.wob_kn, '#1b1f24', 6);
  }
}

function drawParams(canvas) {
  const law = $('law-select').value;
  const updates = state.updates.filter((u) => u.laws.some((l) => l.law === law));
  if (!law || updates.length === 0) return message(canvas, 'no posterior yet');
  const spec = state.meta && state.meta.laws ? state.meta.laws.find((l) => l.name === law) : null;
  const count = updates[0].laws.find((l) => l.law === law).mean.length;
  const rowHeight = 90;
  // Below the last panel: its time ticks and the axis's name.
  canvas.style.height = `${rowHeight * count + 36}px`;
  const { g, w, h } = surface(canvas);
  const x = [updates[0].end_s, updates[updates.length - 1].end_s];
  const times = ticks(x[0], x[1], 6);
  for (let j = 0; j < count; j++) {
    const rows = updates.map((u) => u.laws.find((l) => l.law === law));
    const lo = rows.map((r) => r.q01[j]);
    const hi = rows.map((r) => r.q99[j]);
    const y = extent(lo.concat(hi));
    const box = { left: 58, right: w - 12, top: j * rowHeight + 8, bottom: (j + 1) * rowHeight - 8 };
    const px = (v) => box.left + ((v - x[0]) / (x[1] - x[0] || 1)) * (box.right - box.left);
    const py = (v) => box.bottom - ((v - y[0]) / (y[1] - y[0] || 1)) * (box.bottom - box.top);
    g.strokeStyle = '#eef0f2';
    g.lineWidth = 1;
    for (const t of times) {
      g.beginPath();
      g.moveTo(px(t), box.top);
      g.lineTo(px(t), box.bottom);
      g.stroke();
    }
    g.strokeStyle = '#9aa3ad';
    g.strokeRect(box.left, box.top, box.right - box.left, box.bottom - box.top);
    const ends = updates.map((u) => u.end_s);
    fillBetween(g, px, py, ends, hi, lo, color(law), 0.25);
    polyline(g, px, py, ends, rows.map((r) => r.mean[j]));
    g.strokeStyle = color(law);
    g.lineWidth = 1.5;
    g.stroke();
    changeLines({ g, px, py }, state.updates, y);
    const p = spec ? spec.params[j] : null;
    g.fillStyle = '#1b1f24';
    g.font = '11px system-ui, sans-serif';
    g.textAlign = 'left';
    g.fillText(p ? `${p.name}, ${p.unit}` : `parameter ${j + 1}`, box.left + 4, box.top + 12);
    g.textAlign = 'right';
    g.fillStyle = '#5b6570';
    g.fillText(short(y[1]), box.left - 4, box.top + 10);
    g.fillText(short(y[0]), box.left - 4, box.bottom);
    if (j === count - 1) {
      g.textAlign = 'center';
      for (const t of times) g.fillText(short(t), px(t), box.bottom + 14);
      g.fillText('end of the window along the record, s', (box.left + box.right) / 2, h - 4);
    }
  }
}

// The window's bit speed and torque along time, one above the other, the stuck band
// (|bit speed| < 1 rpm) shaded, and what the bit shows over the window in the caption.
function drawStrip(canvas) {
  const v = state.view;
  const caption = $('strip-caption');
  const bit = v && v.bit;
  caption.textContent = bit
    ? `Window ${v.window}: the bit stuck ${fixed(bit.stuck_share * 100, 0)} % of the time (|bit speed| < 1 rpm), ` +
      `stick-slip severity ${fixed(bit.severity, 2)} ((max − min) / (2 · mean) of the bit speed; 0 turns steadily, ` +
      `1 or more sticks), mean ${fixed(bit.mean_speed_rpm, 0)} rpm` +
      (bit.mean_wob_kn !== null && bit.mean_wob_kn !== undefined ? `, weight on bit ${short(bit.mean_wob_kn)} kN` : '') +
      (v.depth_m ? `, bit depth ${fixed(v.depth_m[0], 1)}–${fixed(v.depth_m[1], 1)} m.` : '.')
    : '';
  if (!v) return message(canvas, 'no window yet');
  if (v.surface) return drawSurfaceStrip(canvas, v);
  if (surfaceWatch()) return message(canvas, `window ${v.window} of surface channels informed nothing: no bit speed implied`);
  if (!v.time_s || v.time_s.length === 0) return message(canvas, 'the record has no clock: no strip chart');
  drawTimePanels(canvas, v.time_s, [
    { lines: [[v.speed_rpm, '#0072b2']], range: v.speed_rpm.concat([0]), label: 'bit speed, rpm', stuck: true },
    { lines: [[v.torque, '#d55e00']], range: v.torque, label: `torque, ${v.torque_unit}` },
  ]);
}

// A window of surface channels along time: above, the bit speed its strings imply (the 90 %
// band of the posterior's strings, their median) with the top-drive speed and the stuck band;
// below, the surface torque.
function drawSurfaceStrip(canvas, v) {
  const s = v.surface;
  const caption = $('strip-caption');
  const bit = v.bit;
  caption.textContent =
    `Window ${v.window} of surface channels: the bit speed its simulated strings imply (median and 90 % band)` +
    (bit ? `, stuck ${fixed(bit.stuck_share * 100, 0)} % of the time, stick-slip severity ${fixed(bit.severity, 2)}` : '') +
    `, under the top-drive speed the rig streamed; the surface torque below.`;
  const lower = s.bit_rpm.map((q) => q[0]);
  const median = s.bit_rpm.map((q) => q[1]);
  const upper = s.bit_rpm.map((q) => q[2]);
  drawTimePanels(canvas, s.time_s, [
    {
      lines: [[median, '#0072b2'], [s.top_drive_rpm, '#5b6570']],
      range: upper.concat(lower, s.top_drive_rpm, [0]),
      label: 'speed, rpm',
      stuck: true,
      fill: [upper, lower],
      legend: [['bit (implied)', '#0072b2'], ['top drive', '#5b6570']],
    },
    { lines: [[s.surface_torque, '#d55e00']], range: s.surface_torque, label: `surface torque, ${v.torque_unit}` },
  ]);
}

// Panels one above the other along `time_s` (time along the record, s), each with its lines
// ([values, colour]), the values its y axis spans (`range`) and its label; where asked, the
// stuck band (|speed| < 1 rpm, where a downhole tool counts the bit stuck) shaded, a band
// between `fill`'s upper and lower values, and a legend of [text, colour].
function drawTimePanels(canvas, time_s, panels) {
  const { g, w, h } = surface(canvas);
  const x = extent(time_s);
  const height = (h - 38) / panels.length;
  const times = ticks(x[0], x[1], 6);
  panels.forEach((panel, k) => {
    const y = extent(panel.range);
    const top = 8 + k * height;
    const box = { left: 58, right: w - 12, top, bottom: top + height - 12 };
    const px = (t) => box.left + ((t - x[0]) / (x[1] - x[0] || 1)) * (box.right - box.left);
    const py = (u) => box.bottom - ((u - y[0]) / (y[1] - y[0] || 1)) * (box.bottom - box.top);
    if (panel.stuck) {
      g.fillStyle = 'rgba(179, 38, 30, 0.15)';
      const [a, b] = [py(Math.min(1, y[1])), py(Math.max(-1, y[0]))];
      g.fillRect(box.left, a, box.right - box.left, b - a);
    }
    if (panel.fill && panel.fill[0].length === time_s.length) {
      fillBetween(g, px, py, time_s, panel.fill[0], panel.fill[1], 'rgb(0, 114, 178)', 0.2);
    }
    g.strokeStyle = '#9aa3ad';
    g.lineWidth = 1;
    g.strokeRect(box.left, box.top, box.right - box.left, box.bottom - box.top);
    for (const [line, colour] of panel.lines) {
      if (line.length !== time_s.length) continue;
      polyline(g, px, py, time_s, line);
      g.strokeStyle = colour;
      g.lineWidth = 1.2;
      g.stroke();
    }
    g.fillStyle = '#5b6570';
    g.font = '11px system-ui, sans-serif';
    g.textAlign = 'right';
    for (const t of ticks(y[0], y[1], 3)) g.fillText(short(t), box.left - 4, py(t) + 4);
    g.save();
    g.translate(12, (box.top + box.bottom) / 2);
    g.rotate(-Math.PI / 2);
    g.textAlign = 'center';
    g.fillText(panel.label, 0, 0);
    g.restore();
    let at = box.left + 6;
    for (const [text, colour] of panel.legend || []) {
      g.textAlign = 'left';
      g.fillStyle = colour;
      g.fillText(text, at, box.top + 12);
      at += g.measureText(text).width + 16;
    }
    if (k === panels.length - 1) {
      g.fillStyle = '#5b6570';
      g.textAlign = 'center';
      for (const t of times) g.fillText(short(t), px(t), box.bottom + 14);
      g.fillText('time along the record, s', (box.left + box.right) / 2, h - 4);
    }
  });
}

document.addEventListener('DOMContentLoaded', () => {
  $('print').addEventListener('click', () => window.print());
  $('law-select').addEventListener('change', (e) => {
    e.target.dataset.chosen = '1';
    schedule();
  });
  window.addEventListener('resize', schedule);
  connect();
});
