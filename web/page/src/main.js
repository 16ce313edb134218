// The participant's study page: the study window's screens (welcome, consent, instructions,
// familiarization, trials, breaks, end) over the server's API. A trial is drawn from the
// server's description of it (protocols::screen::Screen: panes, schedule, answer widget;
// lab::scene: the figures), the same the window draws; the page holds no method's name.
// Every rule of a method (which trial comes next, scoring, staircase levels) stays on the
// server; the page plays the clips by time, measures its frames and posts the answer.
import { Stage, parseClip, webglInfo } from './render.js';
import { Presentation } from './presentation.js';
import CAPABILITIES from './capabilities.json';

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

/** ASCII lower case: the server matches options and yes/no without regard to it. */
const asciiLower = (s) => s.replace(/[A-Z]/g, (c) => c.toLowerCase());
/** A number as the server reads one (a decimal, optionally signed, with an exponent). */
const NUMBER = /^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$/;
const YES_NO = new Map([['yes', 'yes'], ['y', 'yes'], ['no', 'no'], ['n', 'no']]);

/**
 * The answer `raw` to subject field `f` as the server stores it (`{ value }`), or why the
 * server would refuse it (`{ why }`): the server's own rules for the field's kind, in its
 * words (`f.hint`). `unreadable`: the browser holds an entry it cannot read as a number.
 */
function checkField(f, raw, unreadable) {
  const v = raw.trim();
  const refuse = (why) => ({ why: `${f.label}: ${why}` });
  if (!v && !unreadable) return refuse(`${f.hint} (required)`);
  if ([...v].length > f.max_chars || /[\u0000-\u001f\u007f-\u009f]/.test(v)) {
    return refuse(`at most ${f.max_chars} characters, on one line`);
  }
  if (f.kind === 'number') {
    const x = NUMBER.test(v) ? Number(v) : NaN;
    const ok = Number.isFinite(x) && (!f.integer || Number.isInteger(x)) && x >= f.min && x <= f.max;
    return ok ? { value: v } : refuse(f.hint);
  }
  if (f.kind === 'choice') {
    const o = f.options.find((x) => asciiLower(x) === asciiLower(v));
    return o === undefined ? refuse(f.hint) : { value: o };
  }
  if (f.kind === 'yes_no') {
    const a = YES_NO.get(asciiLower(v));
    return a === undefined ? refuse(f.hint) : { value: a };
  }
  return { value: v };
}

/**
 * The welcome form's row for subject field `f`: its label, its input (a text box, a number
 * box with the field's range, or a radio button per option), and the line under it where a
 * refusal's reason shows. Returns { field, els, raw(), unreadable(), given(), say(why), focus() }.
 */
function fieldRow(f) {
  const id = `field-${f.name}`;
  const reason = Object.assign(document.createElement('p'), { id: `${id}-reason`, className: 'field-reason warn' });
  reason.setAttribute('aria-live', 'polite');
  const say = (why) => { reason.textContent = why || ''; };
  if (f.options) {
    const label = Object.assign(document.createElement('span'), { id: `${id}-label`, className: 'field-label', textContent: f.label });
    const group = Object.assign(document.createElement('div'), { className: 'options' });
    group.setAttribute('role', 'radiogroup');
    group.setAttribute('aria-labelledby', label.id);
    group.setAttribute('aria-describedby', reason.id);
    const radios = f.options.map((o, k) => {
      const radio = Object.assign(document.createElement('input'), { type: 'radio', name: f.name, value: o, id: `${id}-${k}` });
      const option = Object.assign(document.createElement('label'), { htmlFor: radio.id, className: 'option' });
      option.append(radio, Object.assign(document.createElement('span'), { textContent: o }));
      group.append(option);
      return radio;
    });
    const picked = () => radios.find((r) => r.checked);
    return {
      field: f, els: [label, group, reason], say,
      raw: () => (picked() ? picked().value : ''),
      unreadable: () => false,
      given: () => !!picked(),
      focus: () => (picked() || radios[0]).focus(),
    };
  }
  const label = Object.assign(document.createElement('label'), { htmlFor: id, className: 'field-label', textContent: f.label });
  const input = Object.assign(document.createElement('input'), { id, name: f.name, type: 'text', maxLength: f.max_chars, autocomplete: 'off' });
  if (f.kind === 'number') {
    Object.assign(input, { type: 'number', min: f.min, max: f.max, step: f.integer ? '1' : 'any', inputMode: f.integer ? 'numeric' : 'decimal' });
  }
  input.setAttribute('aria-describedby', reason.id);
  // A number box holds an entry it cannot read (`1e`) as an empty value.
  const unreadable = () => !!(input.validity && input.validity.badInput);
  return {
    field: f, els: [label, input, reason], say,
    raw: () => input.value,
    unreadable,
    given: () => input.value.trim() !== '' || unreadable(),
    focus: () => input.focus(),
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
  const rows = resumed ? [] : info.fields.map(fieldRow);
  const fields = $('welcome-fields');
  fields.replaceChildren(...rows.flatMap((r) => r.els));
  fields.hidden = rows.length === 0;
  $('welcome-consent').hidden = resumed || !info.consent;
  $('consent-text').textContent = info.consent || '';
  $('begin-error').textContent = '';
  const missing = () => {
    const todo = [];
    const empty = rows.filter((r) => !r.given()).map((r) => r.field.label);
    if (empty.length) todo.push(`answer ${empty.join(', ')}`);
    if (!resumed && info.consent && !$('consent').checked) todo.push('tick “I agree to take part”');
    return todo.length ? `To begin, ${todo.join(' and ')}.` : null;
  };
  const check = (r) => checkField(r.field, r.raw(), r.unreadable());
  const update = () => { $('begin-missing').textContent = missing() || ''; };
  // A reason shows once an answer is given (or Begin pressed) and goes once it is right.
  fields.oninput = (e) => {
    const r = rows.find((x) => x.els[1].contains(e.target));
    if (r && r.els[2].textContent) r.say(check(r).why);
    update();
  };
  fields.onchange = (e) => {
    const r = rows.find((x) => x.els[1].contains(e.target));
    if (r && r.given()) r.say(check(r).why);
    update();
  };
  $('consent').onchange = update;
  update();
  for (;;) {
    $('begin').disabled = false;
    await new Promise((go) => {
      $('begin').onclick = go;
      document.onkeydown = (e) => { if (e.key === 'Enter') { e.preventDefault(); go(); } };
    });
    document.onkeydown = null;
    if (resumed) return;
    // The server's rules, here first: nothing is sent while a field would be refused.
    const values = {};
    let wrong = null;
    for (const r of rows) {
      const c = check(r);
      r.say(c.why);
      if (c.why && !wrong) wrong = r;
      else if (!c.why) values[r.field.name] = c.value;
    }
    update();
    $('begin-error').textContent = '';
    if (wrong) { wrong.focus(); continue; }
    if (info.consent && !$('consent').checked) { $('consent').focus(); continue; }
    if (!state.env) state.env = await environment();
    state.env.fullscreen = !!document.fullscreenElement;
    $('begin').disabled = true;
    try {
      await call('POST', api('begin'), { fields: values, consent: $('consent').checked, environment: state.env }, { retry: true });
      return;
    } catch (e) {
      if (e.status !== 400) throw e;
      // Refused by the server: its reason, beside the field it names too.
      $('begin-error').textContent = e.message;
      const r = rows.find((x) => e.message.startsWith(`${x.field.label}:`));
      if (r) { r.say(e.message); r.focus(); }
    }
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

/**
 * The answer widget the screen describes (protocols::methods::AnswerWidget) on the study's
 * scale; returns { enable(open), key(e) }. `onChange(answer, paneRatings)` posts.
 */
function widgets(info, screen, onChange) {
  const box = $('answer-widgets');
  box.replaceChildren();
  const w = screen.answer;
  if (!CAPABILITIES.answer.includes(w.kind)) throw new Error(`this page cannot show a ${w.kind} answer`);
  $('question').textContent = w.question || '';
  $('continue').hidden = w.kind === 'choice';
  if (w.kind === 'choice') return choice(w, onChange);
  if (w.kind === 'slider_grid') return sliders(info, screen, w.words, onChange);
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
    for (const label of w.words) bar.append(Object.assign(document.createElement('div'), { className: 'sec', textContent: label }));
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

  let names;
  if (w.kind === 'rating') {
    names = [w.missing];
    rows.push(scale.kind === 'continuous' ? continuous(0, w.name) : categorical(0));
    box.append(rows[0].el);
  } else {
    names = w.names;
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
  // BT.500's pair of scales appears at the vote, as in the window; until then the
  // stimuli have the screen.
  const atVote = w.kind === 'rating_pair' && scale.kind === 'continuous';
  const n = rows.length;
  const render = () => {
    rows.forEach((r) => r.render());
    box.hidden = atVote && !open;
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
    enable: (o) => { if (o !== open) { open = o; render(); } },
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

/** The name a position's answer has in the DOM (`choice-left`, `choice-neither`). */
function positionName(p) {
  return typeof p === 'string' ? p : `pane-${p.pane}`;
}

/** Buttons of a choice, each with its key (the window's keys, by the same names). */
function choice(w, onChange) {
  let open = false;
  const row = document.createElement('div');
  row.className = 'row';
  const buttons = w.options.map((o) => {
    const b = Object.assign(document.createElement('button'), { type: 'button', textContent: o.label, id: `choice-${positionName(o.answer)}` });
    b.onclick = () => { if (open) onChange({ Choice: o.answer }); };
    row.append(b);
    return b;
  });
  $('answer-widgets').append(row);
  $('missing').textContent = '';
  // A browser names letter keys by the character typed: "a" and "A" both answer A.
  const same = (key, name) => key === name || (name.length === 1 && key.toLowerCase() === name.toLowerCase());
  return {
    enable: (o) => { open = o; buttons.forEach((b) => { b.disabled = !o; }); },
    key: (e) => {
      const o = w.options.find((x) => same(e.key, x.key));
      if (open && o) onChange({ Choice: o.answer });
    },
  };
}

/** A scale value as the page writes it: whole numbers without a decimal point. */
const scaleNumber = (v) => String(Math.round(v * 1000) / 1000);

/**
 * The sliders' scale, beside them: the widget's words (BS.1534's Excellent to Bad, best at
 * the top), each in its equal part of the range, and the two ends marked with their values.
 */
function sliderScale(scale, words) {
  const col = Object.assign(document.createElement('div'), { className: 'slider-scale' });
  col.setAttribute('aria-hidden', 'true');
  const ruler = Object.assign(document.createElement('div'), { className: 'ruler' });
  for (const w of words) ruler.append(Object.assign(document.createElement('div'), { className: 'word', textContent: w }));
  ruler.append(
    Object.assign(document.createElement('span'), { className: 'end top', textContent: scaleNumber(scale.max) }),
    Object.assign(document.createElement('span'), { className: 'end bottom', textContent: scaleNumber(scale.min) }),
  );
  col.append(document.createElement('span'), ruler, document.createElement('span'));
  return col;
}

/**
 * MUSHRA: a slider per lettered pane on the study's scale, beside the scale's words; a
 * slider's knob shows only once the pane is rated (by a click, a drag or a key), so that an
 * unrated pane never looks rated at the bottom. Continue once each is set.
 */
function sliders(info, screen, words, onChange) {
  const scale = info.scale;
  const step = scale.step || 1;
  const panes = screen.panes.filter((p) => p.position !== null);
  const values = panes.map(() => null);
  let open = false;
  const box = document.createElement('div');
  box.className = 'sliders';
  box.append(sliderScale(scale, words));
  const inputs = panes.map((p, k) => {
    const col = document.createElement('label');
    col.className = 'slider';
    const input = Object.assign(document.createElement('input'), { type: 'range', min: scale.min, max: scale.max, step, value: (scale.min + scale.max) / 2 });
    input.dataset.pane = k;
    input.setAttribute('aria-label', p.label || '');
    const shown = document.createElement('output');
    const rate = () => { if (open) { values[k] = Number(input.value); render(); } };
    input.oninput = rate;
    // A click on the knob's unseen place, or a key that leaves the value, rates it too.
    input.onpointerup = rate;
    input.onkeyup = (e) => { if (e.key.startsWith('Arrow') || e.key.startsWith('Page') || e.key === 'Home' || e.key === 'End') rate(); };
    col.append(Object.assign(document.createElement('strong'), { textContent: p.label || '' }), input, shown);
    box.append(col);
    return { input, shown };
  });
  $('answer-widgets').append(box);
  const render = () => {
    inputs.forEach(({ input, shown }, k) => {
      input.disabled = !open;
      input.classList.toggle('unset', values[k] === null);
      input.setAttribute('aria-valuetext', values[k] === null ? 'not rated' : String(values[k]));
      shown.textContent = values[k] === null ? '–' : String(values[k]);
    });
    const left = panes.filter((_, k) => values[k] === null).map((p) => p.label);
    $('continue').disabled = !(open && left.length === 0);
    $('missing').textContent = open && left.length ? `Rate ${left.join(', ')} to continue.` : '';
  };
  $('continue').onclick = () => {
    if (open && values.every((v) => v !== null)) onChange({ Rating: values[0] }, values.slice());
  };
  render();
  return {
    enable: (o) => { if (o !== open) { open = o; render(); } },
    key: (e) => { if (open && e.key === 'Enter') $('continue').click(); },
  };
}

/** Columns of a grid of `n` panes of aspect 4:3 in a `w` × `h` area that make them largest. */
function gridColumns(n, w, h) {
  let best = 1;
  let size = -1;
  for (let c = 1; c <= Math.max(1, n); c++) {
    const s = Math.min(w / c, (h / Math.ceil(n / c)) * 4 / 3);
    if (s > size) { size = s; best = c; }
  }
  return best;
}

/**
 * Where the panes go in a `w` × `h` stage for what a frame shows, as the window lays them
 * out (window/src/screens.rs stimuli_panel): side by side two squares, one stimulus 16:9,
 * a grid of 4:3 cells each with its name above. Returns [{ pane, x, y, w, h, name }].
 */
function layout(screen, show, w, h) {
  const labelled = screen.panes.some((p) => p.label);
  if (show.show === 'both') {
    const gap = 12;
    const band = labelled ? 44 : 0;
    const pw = (w - gap) / 2;
    const ph = Math.min(pw, h - band);
    const top = h / 2 - (ph - band) / 2;
    return [0, 1].map((k) => ({ pane: k, x: k * (pw + gap), y: top, w: pw, h: ph, name: screen.panes[k] && screen.panes[k].label }));
  }
  if (show.show === 'one' || show.show === 'test') {
    const k = show.show === 'one' && screen.panes[0] && positionName(show.position) !== positionName(screen.panes[0].position) ? 1 : 0;
    const ph = h - 40;
    const pw = Math.min(ph * 16 / 9, w);
    return [{ pane: k, x: (w - pw) / 2, y: h / 2 + 20 - ph / 2, w: pw, h: ph, name: null }];
  }
  if (show.show === 'grid') {
    const n = screen.panes.length;
    const [gap, band] = [8, 26];
    const cols = gridColumns(n, w, h);
    const rows = Math.ceil(n / cols);
    const cw = (w - gap * (cols - 1)) / cols;
    const ch = (h - gap * (rows - 1)) / rows;
    return screen.panes.map((p, k) => {
      const [c, r] = [k % cols, Math.floor(k / cols)];
      return { pane: k, x: c * (cw + gap), y: r * (ch + gap) + band, w: cw, h: Math.max(1, ch - band), name: p.label, band };
    });
  }
  return [];
}

/** The names above the panes, and the step's or pane's label over a single stimulus. */
function drawLabels(screen, frame, rects) {
  const labels = $('labels');
  const out = rects.filter((r) => r.name).map((r) => [r.name, r.x, r.y - (r.band || 44), r.w]);
  if (frame.step.show === 'one') {
    const pane = screen.panes.find((p) => positionName(p.position) === positionName(frame.step.position));
    const text = (pane && pane.label) || frame.label;
    if (text) out.push([text, 0, 0, labels.clientWidth]);
  } else if (frame.label) out.push([frame.label, 0, 0, labels.clientWidth]);
  const key = JSON.stringify(out);
  if (labels.dataset.text === key) return;
  labels.dataset.text = key;
  labels.replaceChildren(...out.map(([text, x, y, w]) => {
    const d = Object.assign(document.createElement('div'), { textContent: text });
    Object.assign(d.style, { left: `${x}px`, top: `${Math.max(0, y)}px`, width: `${w}px` });
    return d;
  }));
}

/** Plays trial `t` until the participant answers; resolves with the request to post. */
function runTrial(info, t, clips) {
  const { screen, scene } = t.page;
  return new Promise((resolve) => {
    document.body.dataset.trial = String(t.index);
    document.body.dataset.trials = t.indices.join(',');
    show('trial');
    const stage = state.stage;
    stage.load(scene, clips);
    const pres = new Presentation(screen.schedule);
    let intervals = [];
    let phases = [];
    let last = null;
    let hidden = false;
    let answered = false;
    let gateOpen = null;
    const w = widgets(info, screen, (answer, paneRatings) => {
      if (answered || !pres.shownOnce) return;
      answered = true;
      // Its handlers go now, not at this trial's next frame: a slow frame can come after
      // the next trial has put its own in place, and would take those away.
      document.onkeydown = null;
      document.onvisibilitychange = null;
      // Closed once given; a refused answer opens again only after the trial replays.
      document.body.dataset.open = '0';
      const now = performance.now();
      resolve({
        index: t.index,
        answer,
        replays: pres.replays,
        response_time_ms: Math.max(0, Math.round(now - gateOpen)),
        played_ms: now - pres.firstStart,
        pane_ratings: paneRatings || [],
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
    const canvas = $('view');
    const frame = (now) => {
      if (answered) return;
      const f = pres.at(now);
      if (last !== null) {
        intervals.push(now - last);
        phases.push(f.phase);
      }
      last = now;
      if (f.finished && gateOpen === null) gateOpen = now;
      const rects = layout(screen, f.step, canvas.clientWidth, canvas.clientHeight);
      stage.draw(rects, f.clipTime);
      // What the frame drawn showed, when and where (tests compare it with the window's
      // drawing of the same); a global, not the DOM, so nothing is restyled per frame.
      window.drawn = { trial: t.index, show: f.step.show, clipTime: f.clipTime, panes: rects.map((r) => [r.pane, r.x, r.y, r.w, r.h]) };
      drawLabels(screen, f, rects);
      const open = pres.shownOnce;
      w.enable(open);
      document.body.dataset.open = open ? '1' : '0';
      document.body.dataset.trial = String(t.index);
      replay.hidden = !pres.canReplay();
      $('watch').hidden = open;
      $('vote').hidden = !(f.past && f.step.show === 'grey');
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
    if (t.page.screen.break_before && state.reached !== null && state.reached !== t.index) {
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
    const bufs = await Promise.all([...Array(t.clips).keys()].map((k) => call('GET', api(`clip/${t.index}/${k}`), undefined, { retry: true, binary: true })));
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
