// A trial's presentation schedule, as the study window runs it (window/src/flow.rs):
// side by side, both clips `playback_count` times; sequential, first, grey, second; DSCQS
// (BT.500), A, grey, B, grey, A, grey, B, then the vote on grey. Answers count once the whole
// schedule has been shown; the server checks the time too.

const PHASE = { both: 'both', grey: 'grey' };

export class Presentation {
  constructor(trial, settings, clipS) {
    const clip = clipS > 0 && Number.isFinite(clipS) ? clipS : 1;
    const grey = settings.grey_ms / 1000;
    const plays = Math.max(1, settings.playback_count);
    const steps = [];
    const addGrey = () => { if (grey > 0) steps.push({ show: 'grey', label: null, d: grey, phase: PHASE.grey }); };
    if (trial.arrangement === 'side_by_side') {
      for (let k = 0; k < plays; k++) steps.push({ show: 'both', label: null, d: clip, phase: PHASE.both });
    } else if (trial.arrangement === 'sequential') {
      for (let k = 0; k < plays; k++) {
        if (k > 0) addGrey();
        steps.push({ show: 0, label: '1', d: clip, phase: 'first' });
        addGrey();
        steps.push({ show: 1, label: '2', d: clip, phase: 'second' });
      }
    } else {
      ['a', 'b', 'a', 'b'].forEach((p, i) => {
        if (i > 0) addGrey();
        steps.push({ show: p === 'a' ? 0 : 1, label: p.toUpperCase(), d: clip, phase: p });
      });
    }
    this.steps = steps;
    this.arrangement = trial.arrangement;
    this.loop = settings.loop;
    this.maxReplays = settings.max_replays;
    this.replays = 0;
    this.shownOnce = false;
    this.start = null;
    this.firstStart = null;
  }

  /** What to draw at `now` (ms, performance clock). */
  at(now) {
    if (this.start === null) {
      this.start = now;
      if (this.firstStart === null) this.firstStart = now;
    }
    let t = Math.max(0, (now - this.start) / 1000);
    for (const s of this.steps) {
      if (t < s.d) return { show: s.show, label: s.label, clipTime: t, finished: this.shownOnce, past: false, phase: s.phase };
      t -= s.d;
    }
    this.shownOnce = true;
    const last = this.steps[this.steps.length - 1];
    if (this.arrangement === 'side_by_side') {
      return { show: 'both', label: null, clipTime: this.loop ? t % Math.max(1e-3, last.d) : last.d, finished: true, past: true, phase: 'answer' };
    }
    return { show: 'grey', label: null, clipTime: 0, finished: true, past: true, phase: 'answer' };
  }

  canReplay() {
    return this.shownOnce && (this.maxReplays === null || this.replays < this.maxReplays);
  }

  replay(now) {
    if (!this.canReplay()) return false;
    this.replays += 1;
    this.start = now;
    return true;
  }

  /** From the start, as if never shown (the page was hidden during the stimuli). */
  restart(now) {
    this.start = now;
    this.firstStart = now;
    this.shownOnce = false;
  }
}
