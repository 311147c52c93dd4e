//! The servo's opt-in real-time scheduling: asked for, it is either granted (and the physics
//! then really runs under SCHED_FIFO: checked from inside the tick, so a report that claims it
//! without doing it fails) or refused with a reason; not asked for, the servo stays ordinary.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;

use palpate_core::{StepError, Vec3};
use palpate_haptics::devices::{Hand, HandParams};
use palpate_haptics::realtime::current_thread_is_fifo;
use palpate_haptics::{HapticCore, Identity, Physics, Realtime, Servo, ServoConfig, Wall};

/// The wall, noting whether its ticks ran under SCHED_FIFO.
struct Watched {
    wall: Wall,
    fifo: Arc<AtomicBool>,
    ticks: Arc<AtomicU64>,
}

impl Physics for Watched {
    fn tick(&mut self, tool: &Vec3, dt: f64) -> Result<Vec3, StepError> {
        if self.ticks.fetch_add(1, Ordering::Relaxed) == 10 {
            self.fifo.store(current_thread_is_fifo(), Ordering::Relaxed);
        }
        self.wall.tick(tool, dt)
    }
    fn tool(&self) -> Option<Vec3> {
        self.wall.tool()
    }
    fn checkpoint(&mut self) {
        self.wall.checkpoint()
    }
    fn restore(&mut self) {
        self.wall.restore()
    }
    fn is_finite(&self) -> bool {
        self.wall.is_finite()
    }
    fn identity(&self) -> Identity {
        self.wall.identity()
    }
}

fn run(realtime: bool) -> (Realtime, bool) {
    let fifo = Arc::new(AtomicBool::new(false));
    let ticks = Arc::new(AtomicU64::new(0));
    let physics = Watched { wall: Wall::new(Vec3::zeros(), Vec3::z(), 2000.0, 2.0), fifo: fifo.clone(), ticks: ticks.clone() };
    let hand = Hand::new(HandParams::default(), Vec3::new(0.0, 0.0, 0.005));
    let cfg = ServoConfig { realtime, max_ticks: Some(200), ..Default::default() };
    let core = HapticCore::with_config(Box::new(physics), &cfg, &hand).unwrap();
    let report = Servo::start(core, Box::new(hand), &cfg).unwrap().join();
    assert!(ticks.load(Ordering::Relaxed) >= 200);
    (report.realtime, fifo.load(Ordering::Relaxed))
}

#[test]
fn a_realtime_servo_runs_its_ticks_under_sched_fifo_or_says_why_not() {
    let (rt, fifo) = run(true);
    match rt {
        Realtime::Granted(p) => {
            assert_eq!(p, palpate_haptics::realtime::SERVO_PRIORITY);
            assert!(fifo, "granted, yet the ticks did not run under SCHED_FIFO");
        }
        Realtime::Refused(why) => {
            assert!(!fifo);
            assert!(why.contains("SCHED_FIFO"), "{why}");
            eprintln!("real-time scheduling refused here: {why}");
        }
        Realtime::Off => panic!("asked for real time, the report says it was not"),
    }
    let (rt, fifo) = run(false);
    assert_eq!(rt, Realtime::Off);
    assert!(!fifo, "not asked for, the servo must stay an ordinary thread");
}
