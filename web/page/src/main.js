// The participant's study page: the study window's screens (welcome, consent, instructions,
// familiarization, MOS / DSCQS / 2AFC trials, breaks, end) over the server's API. Every rule
// of the protocol (which trial comes next, scoring, staircase levels) stays on the server;
// the page plays the two clips by time, measures its frames and posts the answer.
import { Stage, parseClip, webglInfo } from './render.js';
import { Presentation } from './presentation.js';

const $ = (id) => document.getElementById(id);
const SCREENS = ['message', 'check', 'welcome', 'break', 'trial', 'gap', 'end'];

const state = {
  subject: null,
  token: null,
  info: null,
  env: null,
  stage: null,
  trial: null,
  // The trial this page last asked for (none since it loaded): a break shows only before a
  // trial after another, not after a reload nor when a refused answer's trial comes again.
  reached: null,
};

function show(name) {
  // Answers open only once a trial's frame loop says so.
  document.body.dataset.open = '0';
  for (const s of SCREENS) $(`screen-${s}`).hidden = s !== name;
  $('progress').hidden = !(name === 'trial' || name === 'gap');
  document.body.dataset.screen = name;
}

function message(title, text) {
  $('message-title').textContent = title;
  $('message-text').textContent = text;
  show('message');
}

// ---- the API --------------------------------------------------------------------------

class ApiError extends Error {
  constructor(status, text) {
    super(text);
    this.status = status;
  }
}

async function call(method, path, body, { retry = false, binary = false } = {}) {
  const headers = {};
  if (state.token) headers.Authorization = `Bearer ${state.token}`;
  if (body !== undefined) headers['Content-Type'] = 'application/json';
  const deadline = performance.now() + 120000;
  for (let wait = 250; ; wait = Math.min(wait * 2, 4000)) {
    let r;
    try {
      r = await fetch(path, { method, headers, body: body === undefined ? undefined : JSON.stringify(body) });
    } catch (e) {
      // The server is unreachable (restarting): try again with the same request, which the
      // server acknowledges once however often it arrives.
      if (!retry || performance.now() > deadline) throw new ApiError(0, 'The study server cannot be reached. Please keep this page open and try again in a moment.');
      document.body.dataset.reconnecting = '1';
      await new Promise((ok) => setTimeout(ok, wait));
      continue;
    }
    delete document.body.dataset.reconnecting;
    if (r.ok) return binary ? r.arrayBuffer() : r.json();
    if ((r.status === 502 || r.status === 503 || r.status === 429) && retry && performance.now() < deadline) {
      await new Promise((ok) => setTimeout(ok, wait));
      continue;
    }
    let text = r.statusText;
    try { text = (await r.json()).error || text; } catch (_) { /* not JSON */ }
    throw new ApiError(r.status, text);
  }
}

const api = (path) => `/api/s/${encodeURIComponent(state.subject)}/${path}`;

// ---- the environment check ------------------------------------------------------------

/** Median requestAnimationFrame interval over `n` frames, ms. */
function measureFrames(n) {
  return new Promise((done) => {
    const times = [];
    const tick = (t) => {
      times.push(t);
      if (times.length > n) {
        const d = times.slice(1).map((x, i) => x - times[i]).sort((a, b) => a - b);
        done(d[Math.floor(d.length / 2)]);
      } else requestAnimationFrame(tick);
    };
    requestAnimationFrame(tick);
  });
}

async function environment() {
  const gl = webglInfo();
  const period = await measureFrames(40);
  return {
    webgl2: gl.webgl2,
    webgl_renderer: gl.renderer,
    user_agent: navigator.userAgent,
    screen_px: [screen.width | 0, screen.height | 0],
    window_px: [innerWidth | 0, innerHeight | 0],
    device_pixel_ratio: window.devicePixelRatio || 1,
    refresh_hz: period > 0 ? 1000 / period : 0,
    fullscreen: !!document.fullscreenElement,
  };
}

function unmet(req, env) {
  const out = [];
  if (!env.webgl2) out.push('This browser offers no WebGL2 (3-D graphics).');
  if (env.window_px[0] < req.min_window_px[0] || env.window_px[1] < req.min_window_px[1]) {
    out.push(`The window is ${env.window_px[0]}×${env.window_px[1]}; the study needs at least ${req.min_window_px[0]}×${req.min_window_px[1]}. Enlarge the window.`);
  }
  if (!(env.refresh_hz >= req.min_refresh_hz)) {
    out.push(`The display refreshes at ${env.refresh_hz.toFixed(0)} Hz; the study needs at least ${req.min_refresh_hz} Hz.`);
  }
  if (req.fullscreen && !env.fullscreen) out.push('The study runs in full screen.');
  return out;
}

async function check(study) {
  show('check');
  $('check-title').textContent = study.title;
  const req = study.requirements;
  $('fullscreen').hidden = !req.fullscreen;
  $('fullscreen').onclick = async () => {
    try { await document.documentElement.requestFullscreen(); } catch (_) { /* refused */ }
    await recheck();
  };
  const recheck = async () => {
    $('check-continue').disabled = true;
    state.env = await environment();
    const env = state.env;
    $('check-list').replaceChildren(...[
      `WebGL2: ${env.webgl2 ? 'yes' : 'no'}`,
      `Window: ${env.window_px[0]}×${env.window_px[1]}`,
      `Refresh: ${env.refresh_hz.toFixed(0)} Hz`,
    ].map((t) => Object.assign(document.createElement('li'), { textContent: t })));
    const problems = unmet(req, env);
    $('check-problems').textContent = problems.join(' ');
    $('check-continue').disabled = problems.length > 0;
    document.body.dataset.checked = problems.length ? 'failed' : 'ok';
  };
  addEventListener('resize', () => { if (document.body.dataset.screen === 'check') recheck(); });
  await recheck();
  await new Promise((go) => { $('check-continue').onclick = go; });
  const params = {};
  for (const [k, v] of new URLSearchParams(location.search)) if (k !== 's') params[k] = v;
  const joined = await call('POST', '/api/join', { params, environment: state.env });
  state.subject = joined.subject;
  state.token = joined.token;
  remember();
}

// The link that continues the session: the subject in the query, the token in the
// fragment (never sent to a server, never in a Referer).
function remember() {
  const q = new URLSearchParams(location.search);
  q.set('s', state.subject);
  history.replaceState(null, '', `${location.pathname}?${q}#t=${state.token}`);
  try { localStorage.setItem(`study-session:${location.search}`, JSON.stringify({ s: state.subject, t: state.token })); } catch (_) { /* private mode */ }
}

function recall() {
  const q = new URLSearchParams(location.search);
  const t = new URLSearchParams(location.hash.slice(1)).get('t');
  if (q.get('s') && t) {
    state.subject = q.get('s');
    state.token = t;
    return true;
  }
  try {
    const saved = JSON.parse(localStorage.getItem(`study-session:${location.search}`) || 'null');
    if (saved && saved.s && saved.t) {
      state.subject = saved.s;
      state.token = saved.t;
      remember();
      return true;
    }
  } catch (_) { /* nothing saved */ }
  return false;
}

// ---- welcome --------------------------------------------------------------------------

function planned(info) {
  const p = info.planned;
  return {
    trial: (k) => (p.kind === 'exactly' ? `Trial ${k} of ${p.n}` : p.kind === 'at_most' ? `Trial ${k} of at most ${p.n}` : `Trial ${k}`),
    done: (d) => (p.kind === 'exactly' ? `Trials done: ${d} of ${p.n}.` : p.kind === 'at_most' ? `Trials done: ${d} (at most ${p.n}).` : `Trials done: ${d}.`),
    exact: p.kind === 'exactly' && p.n > 0 ? p.n : null,
  };
}

async function welcome(info) {
  show('welcome');
  $('welcome-title').textContent = info.title;
  document.title = info.title;
  $('welcome-instructions').textContent = info.instructions;
  const resumed = info.state === 'running';
  $('welcome-resume').hidden = !(resumed && info.answered > 0);
  $('welcome-resume').textContent = `Continuing the session: ${info.answered} trials already done.`;
  const fields = $('welcome-fields');
  fields.replaceChildren();
  if (!resumed) {
    for (const f of info.fields) {
      const label = document.createElement('label');
      label.textContent = f.replace(/_/g, ' ');
      label.htmlFor = `field-${f}`;
      const input = Object.assign(document.createElement('input'), { id: `field-${f}`, name: f, type: 'text', maxLength: 200 });
      fields.append(label, input);
    }
  }
  $('welcome-consent').hidden = resumed || !info.consent;
  $('consent-text').textContent = info.consent || '';
  const missing = () => {
    const todo = [];
    const empty = [...fields.querySelectorAll('input')].filter((i) => !i.value.trim()).map((i) => i.name.replace(/_/g, ' '));
    if (empty.length) todo.push(`fill in ${empty.join(', ')}`);
    if (!resumed && info.consent && !$('consent').checked) todo.push('tick “I agree to take part”');
    return todo.length ? `To begin, ${todo.join(' and ')}.` : null;
  };
  const update = () => {
    const m = missing();
    $('begin').disabled = !!m;
    $('begin-missing').textContent = m || '';
  };
  fields.oninput = update;
  $('consent').onchange = update;
  update();
  await new Promise((go) => {
    $('begin').onclick = go;
    document.onkeydown = (e) => { if (e.key === 'Enter' && !$('begin').disabled) go(); };
  });
  document.onkeydown = null;
  if (!resumed) {
    const values = {};
    for (const i of fields.querySelectorAll('input')) values[i.name] = i.value.trim();
    if (!state.env) state.env = await environment();
    state.env.fullscreen = !!document.fullscreenElement;
    await call('POST', api('begin'), { fields: values, consent: $('consent').checked, environment: state.env }, { retry: true });
  }
}

// ---- trials ---------------------------------------------------------------------------

function progress(info, t, ack) {
  const p = planned(info);
  $('trial-text').textContent = p.trial(t.answered + 1);
  $('practice').hidden = !t.practice;
  $('ack').hidden = !ack;
  $('ack').textContent = `${info.answer_recorded}.`;
  const bar = $('progress-bar');
  bar.hidden = !p.exact;
  if (p.exact) bar.value = t.answered / p.exact;
}

function fmt(v) {
  return Number.isInteger(v) ? String(v) : String(v);
}

/** The answer widgets of `info`'s protocol; returns { answer(), key(e), enable(open) }. */
function widgets(info, t, onChange) {
  const box = $('answer-widgets');
  box.replaceChildren();
  const scale = info.scale;
  const cats = scale.categories.map((c) => c.value);
  const range = scale.max - scale.min;
  const fine = scale.step || range / 100;
  const snap = (v) => {
    v = Math.min(scale.max, Math.max(scale.min, v));
    if (scale.step) return scale.min + Math.round((v - scale.min) / scale.step) * scale.step;
    return Math.round(v / fine) * fine;
  };
  const values = [null, null];
  let editing = 0;
  let open = false;
  const rows = [];

  const categorical = (k) => {
    const row = document.createElement('div');
    row.className = 'cats';
    const buttons = scale.categories.map((c) => {
      const cell = document.createElement('div');
      cell.className = 'cat';
      const b = Object.assign(document.createElement('button'), { type: 'button', textContent: c.text, className: 'rating' });
      b.dataset.value = c.value;
      b.dataset.row = k;
      b.onclick = () => { values[k] = c.value; editing = k; render(); };
      cell.append(b);
      if (c.label) cell.append(Object.assign(document.createElement('small'), { textContent: c.label }));
      row.append(cell);
      return b;
    });
    return { el: row, render: () => buttons.forEach((b) => { b.classList.toggle('selected', Number(b.dataset.value) === values[k]); b.disabled = !open; }) };
  };

  const continuous = (k, name) => {
    const wrap = document.createElement('div');
    wrap.className = 'scale';
    wrap.append(Object.assign(document.createElement('strong'), { textContent: name }));
    const bar = document.createElement('div');
    bar.className = 'bar';
    bar.dataset.row = k;
    bar.setAttribute('role', 'slider');
    bar.setAttribute('aria-label', name);
    for (const label of scale.bt500) bar.append(Object.assign(document.createElement('div'), { className: 'sec', textContent: label }));
    const mark = document.createElement('div');
    mark.className = 'mark';
    bar.append(mark);
    const at = (e) => {
      const r = bar.getBoundingClientRect();
      const f = Math.min(1, Math.max(0, (r.bottom - e.clientY) / r.height));
      values[k] = snap(scale.min + f * range);
      editing = k;
      render();
    };
    let drag = false;
    bar.onpointerdown = (e) => { if (!open) return; drag = true; bar.setPointerCapture(e.pointerId); at(e); };
    bar.onpointermove = (e) => { if (drag) at(e); };
    bar.onpointerup = () => { drag = false; };
    wrap.append(bar);
    return {
      el: wrap,
      render: () => {
        mark.hidden = values[k] === null;
        if (values[k] !== null) mark.style.bottom = `${((values[k] - scale.min) / range) * 100}%`;
        bar.classList.toggle('active', editing === k && open);
        bar.setAttribute('aria-valuenow', values[k] === null ? '' : String(values[k]));
      },
    };
  };

  let question;
  let names;
  if (info.protocol === 'staircase') {
    question = info.afc_question;
    const row = document.createElement('div');
    row.className = 'row';
    const pos = t.slots.map((s) => s.position);
    const text = { left: 'Left', right: 'Right', first: 'First', second: 'Second', a: 'A', b: 'B' };
    const choices = pos.map((p) => {
      const b = Object.assign(document.createElement('button'), { type: 'button', textContent: text[p], id: `choice-${p}` });
      b.onclick = () => onChange({ Choice: p });
      row.append(b);
      return b;
    });
    box.append(row);
    $('question').textContent = question;
    const keys = t.arrangement === 'sequential' ? ['1', '2'] : t.arrangement === 'abab' ? ['a', 'b'] : ['ArrowLeft', 'ArrowRight'];
    return {
      complete: false,
      enable: (o) => { open = o; choices.forEach((b) => { b.disabled = !o; }); },
      key: (e) => {
        const i = keys.indexOf(e.key);
        if (open && i >= 0) onChange({ Choice: pos[i] });
      },
    };
  }
  if (info.protocol === 'mos') {
    const labels = info.presentation.labels;
    question = labels ? `Rate the quality of the motion labelled “${labels.test}”` : 'Rate the quality of the compressed motion';
    names = [labels ? `“${labels.test}”` : 'the compressed motion'];
    const name = labels ? labels.test : 'Quality';
    rows.push(scale.kind === 'continuous' ? continuous(0, name) : categorical(0));
    box.append(rows[0].el);
  } else {
    names = t.names;
    question = `Rate the quality of ${names[0]} and of ${names[1]}`;
    if (scale.kind === 'continuous') {
      const both = document.createElement('div');
      both.className = 'scales';
      rows.push(continuous(0, names[0]), continuous(1, names[1]));
      both.append(rows[0].el, rows[1].el);
      box.append(both);
    } else {
      for (const k of [0, 1]) {
        const line = document.createElement('div');
        line.className = 'row';
        line.append(Object.assign(document.createElement('strong'), { textContent: names[k] }));
        rows.push(categorical(k));
        line.append(rows[k].el);
        box.append(line);
      }
    }
  }
  $('question').textContent = question;
  const n = rows.length;
  const render = () => {
    rows.forEach((r) => r.render());
    const done = values.slice(0, n).every((v) => v !== null);
    $('continue').disabled = !(open && done);
    let what;
    if (n === 1) what = names[0];
    else what = values[0] === null && values[1] === null ? `${names[0]} and ${names[1]}` : values[0] === null ? names[0] : names[1];
    const hint = scale.kind === 'categorical' ? `Choose a rating for ${what} to continue.` : `Mark the scale of ${what} to continue.`;
    $('missing').textContent = open && !done ? hint : '';
  };
  const answer = () => (n === 1 ? { Rating: values[0] } : { Pair: { a: values[0], b: values[1] } });
  $('continue').onclick = () => { if (open && values.slice(0, n).every((v) => v !== null)) onChange(answer()); };
  render();
  return {
    enable: (o) => { open = o; render(); },
    key: (e) => {
      if (!open) return;
      const k = e.key;
      if (k === 'Enter') { $('continue').click(); return; }
      if (n === 2 && (k === 'ArrowLeft' || k === 'Backspace')) { editing = 0; render(); return; }
      if (n === 2 && k === 'ArrowRight') { editing = 1; render(); return; }
      const digit = /^[1-9]$/.test(k) ? Number(k) : null;
      const row = editing;
      if (scale.kind === 'continuous') {
        if (digit !== null && digit <= 5) {
          values[row] = snap(scale.min + ((digit - 0.5) / 5) * range);
          if (n === 2 && row === 0) editing = 1;
        }
        const moves = { ArrowUp: fine, ArrowDown: -fine, PageUp: range / 10, PageDown: -range / 10 };
        if (k in moves) {
          const from = values[row] === null ? scale.min + 0.5 * range : values[row];
          values[row] = snap(from + moves[k]);
          e.preventDefault();
        }
      } else {
        if (digit !== null && cats.some((c) => Math.abs(c - digit) < 1e-9)) {
          values[row] = digit;
          if (n === 2 && row === 0) editing = 1;
        }
        if (k === 'ArrowUp' || k === 'ArrowDown') {
          const i = values[row] === null ? -1 : cats.findIndex((c) => Math.abs(c - values[row]) < 1e-9);
          const j = i < 0 ? Math.floor(cats.length / 2) : Math.min(cats.length - 1, Math.max(0, i + (k === 'ArrowUp' ? 1 : -1)));
          values[row] = cats[j];
          e.preventDefault();
        }
      }
      render();
    },
  };
}

/** Plays trial `t` until the participant answers; resolves with the request to post. */
function runTrial(info, t, clips) {
  return new Promise((resolve) => {
    document.body.dataset.trial = String(t.index);
    show('trial');
    const stage = state.stage;
    stage.load(clips);
    const pres = new Presentation(t, info.presentation, t.clip_s);
    const labels = $('labels');
    let intervals = [];
    let phases = [];
    let last = null;
    let hidden = false;
    let answered = false;
    let gateOpen = null;
    const w = widgets(info, t, (answer) => {
      if (answered || !pres.shownOnce) return;
      answered = true;
      // Closed once given; a refused answer opens again only after the trial replays.
      document.body.dataset.open = '0';
      const now = performance.now();
      resolve({
        index: t.index,
        answer,
        replays: pres.replays,
        response_time_ms: Math.max(0, Math.round(now - gateOpen)),
        played_ms: now - pres.firstStart,
        intervals,
        phases,
        hidden,
        fullscreen: !!document.fullscreenElement,
      });
    });
    const replay = $('replay');
    replay.onclick = () => { pres.replay(performance.now()); };
    document.onkeydown = (e) => w.key(e);
    const restart = () => {
      // Hidden during the stimuli: the trial is shown again from the start (the study's
      // rule), as the window does after a pause.
      pres.restart(performance.now());
      intervals = [];
      phases = [];
      last = null;
      gateOpen = null;
    };
    document.onvisibilitychange = () => {
      if (document.hidden && !pres.shownOnce) {
        if (info.hidden_rule === 'exclude') hidden = true;
        else restart();
      }
    };
    const frame = (now) => {
      if (answered) { document.onkeydown = null; document.onvisibilitychange = null; return; }
      const f = pres.at(now);
      if (last !== null) {
        intervals.push(now - last);
        phases.push(f.phase);
      }
      last = now;
      if (f.finished && gateOpen === null) gateOpen = now;
      stage.draw(f.show, f.clipTime);
      const open = pres.shownOnce;
      w.enable(open);
      document.body.dataset.open = open ? '1' : '0';
      document.body.dataset.trial = String(t.index);
      replay.hidden = !pres.canReplay();
      $('watch').hidden = open;
      $('vote').hidden = !(f.past && f.show === 'grey');
      const names = f.show === 'both' ? t.slots.map((s) => s.label || '') :
        typeof f.show === 'number' ? [t.slots[f.show].label || f.label || ''] : [];
      const text = names.join('|');
      if (labels.dataset.text !== text) {
        labels.dataset.text = text;
        labels.replaceChildren(...names.map((n) => Object.assign(document.createElement('div'), { textContent: n })));
      }
      requestAnimationFrame(frame);
    };
    requestAnimationFrame(frame);
  });
}

async function trials(info) {
  const p = planned(info);
  for (;;) {
    const t = await call('GET', api('trial'), undefined, { retry: true });
    if (t.done) return t;
    if (t.break_before && state.reached !== null && state.reached !== t.index) {
      show('break');
      $('break-done').textContent = p.done(t.answered);
      $('break-bar').hidden = !p.exact;
      if (p.exact) $('break-bar').value = t.answered / p.exact;
      await new Promise((go) => {
        $('break-continue').onclick = go;
        document.onkeydown = (e) => { if (e.key === 'Enter') go(); };
      });
      document.onkeydown = null;
      // The blank screen while the trial's clips load: the break has visibly ended.
      show('gap');
    }
    state.reached = t.index;
    const bufs = await Promise.all([0, 1].map((k) => call('GET', api(`clip/${t.index}/${k}`), undefined, { retry: true, binary: true })));
    const clips = bufs.map(parseClip);
    progress(info, t, false);
    const request = await runTrial(info, t, clips);
    let reply;
    try {
      reply = await call('POST', api('answer'), request, { retry: true });
    } catch (e) {
      if (e.status === 422) {
        // Refused (played too briefly by the server's clock, or hidden): shown again, the
        // reason on screen until the trial is answered.
        $('trial-error').textContent = e.message;
        document.body.dataset.refusals = String(Number(document.body.dataset.refusals || 0) + 1);
        continue;
      }
      throw e;
    }
    $('trial-error').textContent = '';
    // The blank between trials, with the acknowledgement.
    show('gap');
    progress(info, { ...t, answered: reply.answered }, true);
    $('trial-text').textContent = p.done(reply.answered);
    await new Promise((ok) => setTimeout(ok, Math.max(0, info.presentation.gap_ms)));
  }
}

async function main() {
  try {
    state.stage = null;
    if (!recall()) {
      const study = await call('GET', '/api/study');
      await check(study);
    }
    const info = await call('GET', api('session'), undefined, { retry: true });
    state.info = info;
    if (info.state !== 'finished') {
      await welcome(info);
      state.stage = new Stage($('view'));
      await trials(info);
    }
    const end = await call('GET', api('session'), undefined, { retry: true });
    show('end');
    $('end-text').textContent = 'The session is complete. Thank you!';
    if (end.completion) {
      $('completion').hidden = false;
      $('completion-code').textContent = end.completion.code || '';
      $('completion-code').parentElement.hidden = !end.completion.code;
      const link = $('completion-link');
      if (end.completion.url) {
        link.href = end.completion.url;
        // Back to the platform, which records the completion.
        setTimeout(() => { location.href = end.completion.url; }, 5000);
      } else link.parentElement.hidden = true;
    }
  } catch (e) {
    if (e.status === 401 || e.status === 403) message('This link is not valid', e.message);
    else message('The session stopped', e.message || String(e));
  }
}

main();
