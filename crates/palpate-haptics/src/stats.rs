//! Per-tick timing statistics of the servo: period (start to start), compute time (the tick's
//! work), overruns (ticks that ended after their deadline) and when they happened. Buffers are
//! sized at start; the percentiles are computed after the run, off the servo thread.

/// Overrun times kept (later ones are counted only; 1.6 MB, allocated at start).
pub const OVERRUN_LOG: usize = 100_000;

/// The servo's running record (allocation-free per tick).
#[derive(Debug, Clone)]
pub struct TickTimes {
    period: Vec<f32>,
    compute: Vec<f32>,
    /// Ring position once full.
    next: usize,
    cap: usize,
    ticks: u64,
    overruns: u64,
    overrun_at: Vec<(u64, f64)>,
    period_max: f64,
    compute_max: f64,
    rate_hz: f64,
}

impl TickTimes {
    /// Keeps the last `cap` ticks' times for a loop at `rate_hz`.
    pub fn new(cap: usize, rate_hz: f64) -> TickTimes {
        let cap = cap.max(1);
        TickTimes { period: Vec::with_capacity(cap), compute: Vec::with_capacity(cap), next: 0, cap, ticks: 0, overruns: 0, overrun_at: Vec::with_capacity(OVERRUN_LOG), period_max: 0.0, compute_max: 0.0, rate_hz }
    }

    /// A tick of `period` and `compute` \[s\], an overrun or not, ending at `at` \[s\] since the
    /// start, after simulation tick `tick`.
    pub fn push(&mut self, period: f64, compute: f64, overrun: bool, at: f64, tick: u64) {
        if self.period.len() < self.cap {
            self.period.push(period as f32);
            self.compute.push(compute as f32);
        } else {
            self.period[self.next] = period as f32;
            self.compute[self.next] = compute as f32;
            self.next = (self.next + 1) % self.cap;
        }
        self.ticks += 1;
        self.period_max = self.period_max.max(period);
        self.compute_max = self.compute_max.max(compute);
        if overrun {
            self.overruns += 1;
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
        let pct = |mut v: Vec<f32>, q: f64| -> f64 {
            if v.is_empty() {
                return 0.0;
            }
            v.sort_by(f32::total_cmp);
            v[((q * (v.len() - 1) as f64).round() as usize).min(v.len() - 1)] as f64
        };
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
            overruns: self.overruns,
            overrun_at: self.overrun_at,
        }
    }
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
    pub overruns: u64,
    /// Each logged overrun: (simulation tick, wall time since the start \[s\]).
    pub overrun_at: Vec<(u64, f64)>,
}
