//! Per-tick timing statistics of the servo: period (start to start), compute time (the tick's
//! work, wall clock) and its CPU time (the time the thread actually ran), overruns (ticks that
//! ended after their deadline) and when they happened, and which overruns were the physics' own
//! (CPU time alone longer than the period) rather than the machine's (the thread kept off the
//! CPU mid-tick, or woken late). Buffers are sized at start; the percentiles are computed after
//! the run, off the servo thread.

/// Overrun times kept (later ones are counted only; 1.6 MB, allocated at start).
pub const OVERRUN_LOG: usize = 100_000;

/// The servo's running record (allocation-free per tick).
#[derive(Debug, Clone)]
pub struct TickTimes {
    period: Vec<f32>,
    compute: Vec<f32>,
    cpu: Vec<f32>,
    /// Ring position once full.
    next: usize,
    cap: usize,
    ticks: u64,
    overruns: u64,
    own_overruns: u64,
    /// The last tick was an own overrun (a tick late after it is one too).
    last_own: bool,
    overrun_at: Vec<(u64, f64)>,
    period_max: f64,
    compute_max: f64,
    cpu_max: f64,
    rate_hz: f64,
}

impl TickTimes {
    /// Keeps the last `cap` ticks' times for a loop at `rate_hz`.
    pub fn new(cap: usize, rate_hz: f64) -> TickTimes {
        let cap = cap.max(1);
        TickTimes {
            period: Vec::with_capacity(cap),
            compute: Vec::with_capacity(cap),
            cpu: Vec::with_capacity(cap),
            next: 0,
            cap,
            ticks: 0,
            overruns: 0,
            own_overruns: 0,
            last_own: false,
            overrun_at: Vec::with_capacity(OVERRUN_LOG),
            period_max: 0.0,
            compute_max: 0.0,
            cpu_max: 0.0,
            rate_hz,
        }
    }

    /// A tick of `period`, `compute` (wall clock) and `cpu` (the thread's CPU time over the same
    /// compute) \[s\], an overrun or not, ending at `at` \[s\] since the start, after simulation
    /// tick `tick`. An overrun is the physics' own when `cpu` alone is longer than the period
    /// (`1 / rate_hz`: on a core of its own it would still have overrun), or when it follows an
    /// own overrun with no tick on time between (it started late for that reason).
    pub fn push(&mut self, period: f64, compute: f64, cpu: f64, overrun: bool, at: f64, tick: u64) {
        if self.period.len() < self.cap {
            self.period.push(period as f32);
            self.compute.push(compute as f32);
            self.cpu.push(cpu as f32);
        } else {
            self.period[self.next] = period as f32;
            self.compute[self.next] = compute as f32;
            self.cpu[self.next] = cpu as f32;
            self.next = (self.next + 1) % self.cap;
        }
        self.ticks += 1;
        self.period_max = self.period_max.max(period);
        self.compute_max = self.compute_max.max(compute);
        self.cpu_max = self.cpu_max.max(cpu);
        if !overrun {
            self.last_own = false;
        } else {
            self.overruns += 1;
            // A tick started late by an own overrun just before it is late for the same reason.
            self.last_own = cpu * self.rate_hz > 1.0 || self.last_own;
            if self.last_own {
                self.own_overruns += 1;
            }
            if self.overrun_at.len() < OVERRUN_LOG {
                self.overrun_at.push((tick, at));
            }
        }
    }

    pub fn overruns(&self) -> u64 {
        self.overruns
    }

    /// The summary of a run that lasted `elapsed` \[s\].
    pub fn finish(self, elapsed: f64) -> Stats {
        let pct = |mut v: Vec<f32>, q: f64| percentile(&mut v, q);
        // The first period is the nominal one (there is no previous start): leave it out.
        let periods: Vec<f32> = if self.period.len() > 1 { self.period[1..].to_vec() } else { self.period.clone() };
        Stats {
            rate_hz: self.rate_hz,
            achieved_hz: if elapsed > 0.0 { self.ticks as f64 / elapsed } else { 0.0 },
            ticks: self.ticks,
            elapsed,
            period_p50: pct(periods.clone(), 0.5),
            period_p99: pct(periods, 0.99),
            period_max: self.period_max,
            compute_p50: pct(self.compute.clone(), 0.5),
            compute_p99: pct(self.compute, 0.99),
            compute_max: self.compute_max,
            cpu_p50: pct(self.cpu.clone(), 0.5),
            cpu_p99: pct(self.cpu, 0.99),
            cpu_max: self.cpu_max,
            overruns: self.overruns,
            own_overruns: self.own_overruns,
            overrun_at: self.overrun_at,
        }
    }
}

/// Percentile `q` (0..1) of `v`, sorted in place; 0 when empty.
pub(crate) fn percentile(v: &mut [f32], q: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f32::total_cmp);
    v[((q * (v.len() - 1) as f64).round() as usize).min(v.len() - 1)] as f64
}

/// A run's timing summary (seconds; percentiles over the last `stats_ticks` ticks).
#[derive(Debug, Clone, PartialEq)]
pub struct Stats {
    /// The configured rate \[Hz\] and ticks per second of wall time achieved.
    pub rate_hz: f64,
    pub achieved_hz: f64,
    pub ticks: u64,
    pub elapsed: f64,
    pub period_p50: f64,
    pub period_p99: f64,
    pub period_max: f64,
    pub compute_p50: f64,
    pub compute_p99: f64,
    pub compute_max: f64,
    /// The servo thread's CPU time over each tick's compute (`CLOCK_THREAD_CPUTIME_ID`; the wall
    /// clock's compute where that clock is unavailable): the compute without the time the thread
    /// was kept off the CPU.
    pub cpu_p50: f64,
    pub cpu_p99: f64,
    pub cpu_max: f64,
    pub overruns: u64,
    /// The overruns whose CPU time alone was longer than the period, and those in a row right
    /// after one (late for the same reason): the physics' own. The rest
    /// (`overruns - own_overruns`) fit in the period on the CPU and ended late because the
    /// machine kept the thread off it (preempted mid-tick, or woken late).
    pub own_overruns: u64,
    /// Each logged overrun: (simulation tick, wall time since the start \[s\]).
    pub overrun_at: Vec<(u64, f64)>,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An overrun is the physics' own only when its CPU time alone passed the period, or when it
    /// follows one in a row; a late tick that ran less than a period is the machine's.
    #[test]
    fn own_overruns_are_those_whose_cpu_time_passed_the_period() {
        let mut t = TickTimes::new(16, 1000.0);
        t.push(1e-3, 0.5e-3, 0.5e-3, false, 0.001, 1); // on time
        t.push(1e-3, 3.0e-3, 0.4e-3, true, 0.004, 2); // preempted: the machine's
        t.push(1e-3, 1.5e-3, 1.4e-3, true, 0.006, 3); // its own work
        t.push(1e-3, 0.5e-3, 0.5e-3, true, 0.007, 4); // late because of tick 3
        t.push(1e-3, 0.5e-3, 0.5e-3, false, 0.008, 5); // on time again
        t.push(1e-3, 1.2e-3, 0.3e-3, true, 0.010, 6); // the machine's
        let s = t.finish(0.01);
        assert_eq!((s.overruns, s.own_overruns), (4, 2));
        assert_eq!(s.cpu_max, 1.4e-3);
        assert!(s.cpu_p99 <= s.compute_p99 && s.cpu_p50 <= s.compute_p50);
    }
}
