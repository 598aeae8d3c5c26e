"""Which of two builds of a compiled call runs it, one thread or numba's threads: the faster, timed.

A call shared among threads waits for the slowest of them. On idle cores two threads run
it up to twice as fast; on cores busy with other work a descheduled thread can cost
milliseconds a call. Both builds give the same bits (the callers make sure of that), so
which one runs is a question of time only: :class:`BuildChooser` times both as a run goes
and keeps the faster. Used by the fused stepper's blocked particle steps
(:mod:`animsim.backends.fused`) and the particle contacts' passes
(:mod:`animsim.particle_contacts.stage`).
"""

from __future__ import annotations

#: calls timed on each build before the faster one is kept
TRIAL_CALLS = 3
#: calls between two trials of the build not kept, so a change of the machine's load is followed
RETRY_EVERY = 64
#: and at least this much time (s) on the kept build between two trials: a trial of one
#: thread where two are kept costs about a call more, so short calls would pay for it often
#: (the 100,000-slot fountain, a step a call, spent 1.8 % of its run on them every 64 calls)
RETRY_SECONDS = 0.25
#: after the trials, the other build is kept only when it is this much faster (its median
#: time per step over its last TRIAL_CALLS calls against the kept build's): on idle cores
#: two threads run about 1.4-2x faster, on busy ones one thread 4-8x, while single calls
#: of a run on a shared machine scatter by tens of percent
SWITCH_MARGIN = 1.25


def _median(values: list[float]) -> float:
    """The median of a few floats, as statistics.median gives it."""
    s = sorted(values)
    h = len(s) // 2
    return s[h] if len(s) % 2 else 0.5 * (s[h - 1] + s[h])


class BuildChooser:
    """Which build (one thread or numba's threads) runs the next call: the faster.

    A parallel call waits for its slowest thread. On idle cores two threads halve a
    call's time; on cores busy with other work the wait for a descheduled thread can
    cost milliseconds a call: the 4,500-particle fountain (one step per call) ran in
    0.25 s on one thread and 1.9 s on two while another job kept both cores busy, and a
    step of 100,000 grains' contact passes about 285 ms shared against 140 on one thread
    at a load average of 3.5. Both builds give the same bits, so the caller times them (wall clock, what the user
    waits for): the first calls alternate until each build has TRIAL_CALLS timings, the
    build with the lower time per step (the median of its last TRIAL_CALLS calls) is
    kept, and once RETRY_EVERY calls and RETRY_SECONDS have passed on the kept build, one
    call tries the other build again, which is then kept only if that call was
    SWITCH_MARGIN times faster (a wrong switch on one lucky call is undone once the new
    build's median over its next calls shows it).
    """

    def __init__(self) -> None:
        self.recent: dict[bool, list[float]] = {True: [], False: []}
        self.calls = 0
        #: the build kept (True: numba's threads)
        self.parallel = True
        #: calls and seconds on the kept build since the last trial of the other
        self.kept_calls = 0
        self.kept_seconds = 0.0

    def pick(self) -> bool:
        """True when the next call should run on numba's threads."""
        if self.calls < 2 * TRIAL_CALLS:  # the trials alternate, threads first
            return len(self.recent[True]) <= len(self.recent[False])
        if self.kept_calls >= RETRY_EVERY and self.kept_seconds >= RETRY_SECONDS:
            return not self.parallel
        return self.parallel

    def record(self, parallel: bool, seconds: float, steps: int) -> None:
        """Book a call of ``steps`` steps that took ``seconds`` on that build."""
        if steps <= 0:
            return
        self.calls += 1
        times = self.recent[parallel]
        trials = self.calls <= 2 * TRIAL_CALLS
        if parallel == self.parallel:
            self.kept_calls += 1
            self.kept_seconds += seconds
        else:
            self.kept_calls, self.kept_seconds = 0, 0.0
        if not trials and parallel != self.parallel:
            times.clear()  # a retry of the other build: its old timings are of another load
        times.append(seconds / steps)
        del times[:-TRIAL_CALLS]
        if min(len(self.recent[True]), len(self.recent[False])) >= (TRIAL_CALLS if trials else 1):
            # not NumPy: np.median on three floats took about 37 us, twice a call, which was a
            # twelfth of a fountain step on two threads (statistics.median: about 1.5 us)
            on, off = _median(self.recent[True]), _median(self.recent[False])
            if trials:  # the faster
                self.parallel = on < off
            elif self.parallel:  # a change needs a clear margin (timings of calls scatter)
                self.parallel = not off * SWITCH_MARGIN < on
            else:
                self.parallel = on * SWITCH_MARGIN < off
