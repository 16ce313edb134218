// The experimenter's dashboard: progress per participant, what the crowd rules flag, and the
// running mean score per condition, refreshed every 5 s. The token stays in the fragment.
const token = location.hash.slice(1);

function fill(table, columns, rows) {
  const head = document.createElement('tr');
  for (const c of columns) head.append(Object.assign(document.createElement('th'), { textContent: c }));
  table.replaceChildren(head, ...rows.map((r) => {
    const tr = document.createElement('tr');
    for (const v of r) tr.append(Object.assign(document.createElement('td'), { textContent: v === null || v === undefined ? '' : String(v) }));
    return tr;
  }));
}

async function refresh() {
  const r = await fetch('/api/dashboard', { headers: { Authorization: `Bearer ${token}` } });
  if (!r.ok) {
    document.getElementById('status').textContent = `Refused (${r.status}): open /dashboard.html#TOKEN with the token given to study serve.`;
    return;
  }
  const d = await r.json();
  document.getElementById('title').textContent = `${d.study} (${d.protocol})`;
  const states = Object.entries(d.states).map(([s, n]) => `${n} ${s}`).join(', ');
  const last = d.last_answer_ms === null ? 'no answer yet' : `last answer ${new Date(d.last_answer_ms).toLocaleString()}`;
  document.getElementById('status').textContent = `${d.participants.length} participants (${states || 'none'}); ` +
    `${(100 * d.complete_share).toFixed(0)} % complete; ${last}; updated ${new Date().toLocaleTimeString()}`;
  fill(document.getElementById('participants'),
    ['Subject', 'Source', 'State', 'Answered', 'Gold failed', 'Excluded', 'Hidden trials', 'Not fullscreen', 'Refresh (Hz)'],
    d.participants.map((p) => [p.subject, p.source, p.state, p.answered, p.gold_failed, p.excluded ? 'yes' : '', p.hidden_trials, p.windowed_trials,
      p.refresh_hz === null ? '' : p.refresh_hz.toFixed(1)]));
  fill(document.getElementById('conditions'), ['Condition', 'n', 'Mean'],
    d.conditions.map((c) => [c.condition, c.n, c.mean.toFixed(3)]));
}

refresh();
setInterval(refresh, 5000);
