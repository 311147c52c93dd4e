//! Replay of a recorded interaction: the recorded device inputs, tick by tick.

use std::sync::Arc;

use crate::device::{Device, DeviceInput, DeviceKind, ForceCell, ForceSink};
use crate::record::Recording;

/// Gives a [`Recording`]'s inputs in order; the recording's forces can be compared with what the
/// replay renders ([`crate::record::compare`]).
pub struct Replay {
    inputs: Vec<DeviceInput>,
    sink: Arc<ForceCell>,
}

impl Replay {
    pub fn new(recording: &Recording) -> Replay {
        Replay { inputs: recording.ticks.iter().map(|t| t.input).collect(), sink: Arc::new(ForceCell::default()) }
    }
    pub fn forces(&self) -> Arc<ForceCell> {
        self.sink.clone()
    }
}

impl Device for Replay {
    fn read(&mut self, tick: u64, _dt: f64) -> Option<DeviceInput> {
        // Past the end, hold the last sample (the servo stops there: `finished`).
        self.inputs.get(tick as usize).or(self.inputs.last()).copied()
    }
    fn sink(&self) -> Arc<dyn ForceSink> {
        self.sink.clone()
    }
    fn kind(&self) -> DeviceKind {
        DeviceKind::Simulated
    }
    fn finished(&self, ticks: u64, _dt: f64) -> bool {
        ticks as usize >= self.inputs.len()
    }
}
