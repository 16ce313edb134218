// A trial's schedule as the server describes it (protocols::screen::Schedule, the one the
// study window plays in window/src/flow.rs): its steps in order, what shows after them while
// the subject answers (hold, loop or grey), the replays allowed. Answers count once every
// step has been shown; the server checks the time too.

/** The phase a frame showing `step` belongs to (frames.csv), as Show::phase names it. */
function phaseOf(step) {
  if (step.show === 'one') return typeof step.position === 'string' ? step.position : 'grid';
  return step.show;
}

export class Presentation {
  constructor(schedule) {
    this.steps = schedule.steps;
    this.after = schedule.after;
    this.maxReplays = schedule.max_replays;
    this.replays = 0;
    this.shownOnce = false;
    this.start = null;
    this.firstStart = null;
  }

  /**
   * What to draw at `now` (ms, performance clock): the step (`show`, `position`, `label`),
   * the clip time in seconds, whether the schedule has been shown once (`finished`) and
   * whether this frame is past its end (`past`), and the frame's phase.
   */
  at(now) {
    if (this.start === null) {
      this.start = now;
      if (this.firstStart === null) this.firstStart = now;
    }
    let t = Math.max(0, (now - this.start) / 1000);
    for (const s of this.steps) {
      if (t < s.duration_s) {
        return { step: s, label: s.label, clipTime: t, finished: this.shownOnce, past: false, phase: phaseOf(s) };
      }
      t -= s.duration_s;
    }
    this.shownOnce = true;
    const last = this.steps[this.steps.length - 1] || { show: 'grey', label: null, duration_s: 0 };
    const grey = { show: 'grey', label: null, duration_s: 0 };
    const [step, clipTime] = this.after === 'loop' ? [last, t % Math.max(1e-3, last.duration_s)]
      : this.after === 'hold' ? [last, last.duration_s] : [grey, 0];
    return { step, label: null, clipTime, finished: true, past: true, phase: 'answer' };
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
