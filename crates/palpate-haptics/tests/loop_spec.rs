//! The loop built from its description (`LoopSpec`): the Rust API builds what the CLI and Python
//! build, checks its settings once, and gives the same forces as a loop assembled by hand.

use palpate_core::material::{Damping, Elasticity};
use palpate_core::{Material, ModelBuilder, Vec3};
use palpate_haptics::devices::Scripted;
use palpate_haptics::spec::{BUSY_SPIN, MULTIRATE_SPIN};
use palpate_haptics::{DeviceKind, DeviceSpec, FemOptions, FemPhysics, HapticCore, LoopError, LoopSpec, PhysicsSpec, SafetySpec};

fn material() -> Material {
    Material::new(Elasticity::YoungPoisson { young: 30e3, poisson: 0.4 }, 1000.0, Damping::NONE).unwrap()
}

/// A 60 x 60 x 20 mm slab held at its base.
fn slab() -> palpate_core::Model {
    let mesh = palpate_core::mesh::generate::box_mesh([0.06, 0.06, 0.02], [4, 4, 2]);
    let fixed: Vec<usize> = (0..mesh.n_nodes()).filter(|&i| mesh.points()[i].z <= 1e-9).collect();
    ModelBuilder::new(mesh, material()).fixed_nodes(fixed).build().unwrap()
}

/// A press 2 mm into the slab's top centre and back, 0.3 s.
fn press() -> (Vec<f64>, Vec<Vec3>) {
    let top = Vec3::new(0.03, 0.03, 0.02 + 0.0015);
    (vec![0.0, 0.15, 0.3], vec![top, top - Vec3::z() * 0.002, top])
}

fn scripted_fem() -> LoopSpec {
    let (times, knots) = press();
    LoopSpec::new(PhysicsSpec::Fem { model: slab(), options: FemOptions::default() }, DeviceSpec::Scripted { times, knots })
}

#[test]
fn a_described_loop_gives_the_forces_of_one_assembled_by_hand() {
    let mut spec = scripted_fem();
    spec.single_rate = true;
    spec.record_ticks = 1000;
    let mut built = spec.build().unwrap();
    // Defaults: the simulated class's coupling and limits, a single-rate servo that never sleeps.
    let (dc, ds) = DeviceKind::Simulated.defaults();
    assert_eq!(built.config.coupling, Some(dc));
    assert_eq!(built.config.safety, Some(ds));
    assert_eq!((built.config.physics_rate_hz, built.config.spin), (None, BUSY_SPIN));
    assert!(built.unsafe_note.is_none() && built.hand.is_none() && built.bridge.is_none());
    let n = built.core.run_offline(built.device.as_mut(), u64::MAX);
    assert_eq!(n, 300, "the script's 0.3 s at 1 kHz");

    let (times, knots) = press();
    let mut by_hand = HapticCore::new(Box::new(FemPhysics::new(slab(), FemOptions::default()).unwrap()), 1000.0, dc, ds, built.config.checkpoint_every, 1000);
    let mut dev = Scripted::new(times, knots).unwrap();
    by_hand.run_offline(&mut dev, u64::MAX);
    let (a, b) = (&built.core.recording().unwrap().ticks, &by_hand.recording().unwrap().ticks);
    assert_eq!(a.len(), b.len());
    let fmax = a.iter().map(|t| t.force.norm()).fold(0.0, f64::max);
    assert!(fmax > 0.01, "the press is felt: {fmax} N");
    for (x, y) in a.iter().zip(b) {
        assert_eq!(x.force, y.force);
    }
}

#[test]
fn the_multirate_loop_is_the_default() {
    let built = scripted_fem().build().unwrap();
    assert_eq!((built.config.physics_rate_hz, built.config.spin), (Some(1000.0), MULTIRATE_SPIN));
    let mut slow = scripted_fem();
    slow.rate_hz = 500.0;
    assert_eq!(slow.build().unwrap().config.physics_rate_hz, Some(500.0), "at most the servo's rate");
}

#[test]
fn bad_settings_are_refused_with_their_names() {
    let refused = |edit: &dyn Fn(&mut LoopSpec), what: &str| {
        let mut spec = scripted_fem();
        edit(&mut spec);
        match spec.build() {
            Err(LoopError::Parameter(msg)) => assert!(msg.contains(what), "{msg:?} does not name {what:?}"),
            Err(e) => panic!("{what}: {e}"),
            Ok(_) => panic!("{what}: accepted"),
        }
    };
    refused(&|s| s.coupling.stiffness = Some(-1.0), "coupling_stiffness");
    refused(&|s| s.safety.max_force = Some(f64::NAN), "max_force");
    refused(&|s| s.spin = Some(-1e-3), "spin");
    refused(&|s| s.rate_hz = 50_000.0, "rate");
    refused(
        &|s| {
            s.single_rate = true;
            s.physics_rate_hz = Some(500.0);
        },
        "single-rate",
    );
    // Beyond a Geomagic Touch's rating: refused, unless allowed, and then reported.
    refused(
        &|s| {
            s.kind = Some(DeviceKind::Touch);
            s.safety.max_force = Some(50.0);
        },
        "refused",
    );
    let mut spec = scripted_fem();
    spec.kind = Some(DeviceKind::Touch);
    spec.safety = SafetySpec { max_force: Some(50.0), unsafe_limits: true, ..SafetySpec::default() };
    assert!(spec.build().unwrap().unsafe_note.is_some());
    // A script that goes back in time.
    let spec = LoopSpec::new(PhysicsSpec::Idle, DeviceSpec::Scripted { times: vec![0.0, -1.0], knots: vec![Vec3::zeros(); 2] });
    assert!(matches!(spec.build(), Err(LoopError::Parameter(_))));
}
