//! A scripted device: the handle follows a piecewise-linear trajectory of knots. The knots are
//! the resolved form of `palpate touch`'s script format (TOML segments press / hold / slide /
//! release, or CSV `t,x,y,z`; parsed and resolved against the model's surface by
//! `palpate.touch`), so that the haptic loop and `palpate touch` share one script format.

use std::sync::Arc;

use palpate_core::Vec3;

use crate::device::{Device, DeviceInput, DeviceKind, ForceCell, ForceSink};

/// A trajectory of `(t [s], position [m])` knots, times strictly increasing; the handle at tick
/// `k` is at the trajectory's value for `t = t_0 + (k + 1) dt` (the end of the tick, as
/// `palpate touch`), held at the last knot after the end.
pub struct Scripted {
    times: Vec<f64>,
    knots: Vec<Vec3>,
    sink: Arc<ForceCell>,
    /// Hint for the search (ticks go forward).
    seg: usize,
}

impl Scripted {
    /// Fails on fewer than one knot, mismatched lengths, non-finite values or times not strictly
    /// increasing.
    pub fn new(times: Vec<f64>, knots: Vec<Vec3>) -> Result<Scripted, String> {
        if times.is_empty() || times.len() != knots.len() {
            return Err(format!("a script needs matching times and knots, got {} and {}", times.len(), knots.len()));
        }
        if let Some(i) = times.iter().position(|t| !t.is_finite()).or_else(|| knots.iter().position(|k| !k.iter().all(|c| c.is_finite()))) {
            return Err(format!("knot {i} is not finite"));
        }
        if let Some(i) = times.windows(2).position(|w| w[1] <= w[0]) {
            return Err(format!("knot times must increase strictly: t[{}] = {} after {}", i + 1, times[i + 1], times[i]));
        }
        Ok(Scripted { times, knots, sink: Arc::new(ForceCell::default()), seg: 0 })
    }

    /// The script's length \[s\].
    pub fn duration(&self) -> f64 {
        self.times[self.times.len() - 1] - self.times[0]
    }

    /// The handle at time `t` \[s\] (script time).
    pub fn at(&mut self, t: f64) -> Vec3 {
        let n = self.times.len();
        if t <= self.times[0] {
            return self.knots[0];
        }
        if t >= self.times[n - 1] {
            return self.knots[n - 1];
        }
        if self.times[self.seg] > t {
            self.seg = 0;
        }
        while self.times[self.seg + 1] < t {
            self.seg += 1;
        }
        let (t0, t1) = (self.times[self.seg], self.times[self.seg + 1]);
        let s = (t - t0) / (t1 - t0);
        self.knots[self.seg] + (self.knots[self.seg + 1] - self.knots[self.seg]) * s
    }

    /// The forces sent to this device.
    pub fn forces(&self) -> Arc<ForceCell> {
        self.sink.clone()
    }
}

impl Device for Scripted {
    fn read(&mut self, tick: u64, dt: f64) -> Option<DeviceInput> {
        let t = self.times[0] + (tick + 1) as f64 * dt;
        Some(DeviceInput::at(self.at(t)))
    }
    fn sink(&self) -> Arc<dyn ForceSink> {
        self.sink.clone()
    }
    fn kind(&self) -> DeviceKind {
        DeviceKind::Simulated
    }
    fn finished(&self, ticks: u64, dt: f64) -> bool {
        // Done once the ticks taken reach the last knot's time (within a thousandth of a tick:
        // `n dt` in floating point).
        ticks as f64 * dt >= self.duration() - 1e-3 * dt
    }
}
