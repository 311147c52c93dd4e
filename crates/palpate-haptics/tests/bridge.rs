//! The UDP bridge: a second process drives the loop, and malformed packets are dropped and
//! counted without moving the tool.
//!
//! What a wrong implementation would do:
//! - trust a packet's length (read past a short one, or take the head of a long one), or accept
//!   any version, or a NaN / a position in millimetres, or a late packet, and move the tool;
//! - count nothing (the status line could not say why a device does not move);
//! - block the servo on the socket, or send forces nowhere (the second process gets none).

mod support;

use std::net::SocketAddr;
use std::process::Command;
use std::time::{Duration, Instant};

use palpate_core::Vec3;
use palpate_haptics::bridge::protocol::{self, Reject, STATE_BYTES};
use palpate_haptics::bridge::{Bridge, Client};
use palpate_haptics::{Device, DeviceInput, DeviceKind, HapticCore, Servo, ServoConfig, Wall};

/// Polls until the bridge has received `n` packets in all (a localhost datagram takes a moment).
fn poll_until(b: &mut Bridge, n: u64) -> Option<DeviceInput> {
    let stats = b.stats();
    let t0 = Instant::now();
    let mut got = None;
    while stats.received.load(std::sync::atomic::Ordering::Relaxed) < n && t0.elapsed() < Duration::from_secs(2) {
        got = b.poll().or(got);
        std::thread::sleep(Duration::from_micros(200));
    }
    b.poll().or(got)
}

#[test]
fn malformed_packets_are_dropped_counted_and_never_move_the_tool() {
    let mut bridge = Bridge::localhost(0, DeviceKind::Bridge).unwrap();
    let mut client = Client::connect(bridge.local_addr().unwrap()).unwrap();
    let stats = bridge.stats();
    let p0 = DeviceInput::at(Vec3::new(0.01, 0.02, 0.03));
    client.send(&p0).unwrap(); // seq 1
    assert_eq!(poll_until(&mut bridge, 1), Some(p0));
    let mut core = HapticCore::new(Box::new(Wall::new(Vec3::new(0.0, 0.0, -1.0), Vec3::z(), 1000.0, 0.0)), 1000.0, Default::default(), Default::default(), 250, 0);
    let first = core.step(Some(p0));
    assert_eq!(first.device, p0.position);

    let good = |seq: u32, p: Vec3| protocol::encode_state(seq, &DeviceInput::at(p));
    let moved = Vec3::new(0.5, 0.5, 0.5);
    let with = |f: &dyn Fn(&mut [u8; STATE_BYTES])| {
        let mut b = good(10, moved);
        f(&mut b);
        b.to_vec()
    };
    let put = |b: &mut [u8; STATE_BYTES], at: usize, v: f64| b[at..at + 8].copy_from_slice(&v.to_le_bytes());
    let corpus: Vec<(Vec<u8>, Reject)> = vec![
        (vec![], Reject::Short),
        (good(10, moved)[..79].to_vec(), Reject::Short),
        (good(10, moved)[..8].to_vec(), Reject::Short),
        ([good(10, moved).as_slice(), &[0]].concat(), Reject::Long),
        (vec![0x50; 4000], Reject::Long),
        (vec![0xff; 65_000], Reject::Long),
        (with(&|b| b[0] ^= 1), Reject::BadMagic),
        (vec![0u8; STATE_BYTES], Reject::BadMagic),
        (with(&|b| b[4..6].copy_from_slice(&2u16.to_le_bytes())), Reject::BadVersion),
        (with(&|b| b[4..6].copy_from_slice(&0u16.to_le_bytes())), Reject::BadVersion),
        (with(&|b| b[6..8].copy_from_slice(&2u16.to_le_bytes())), Reject::BadKind),
        (with(&|b| put(b, 16, f64::NAN)), Reject::NonFinite),
        (with(&|b| put(b, 32, f64::INFINITY)), Reject::NonFinite),
        (with(&|b| put(b, 48, f64::NEG_INFINITY)), Reject::NonFinite),
        (with(&|b| put(b, 24, 1e300)), Reject::OutOfRange),
        (with(&|b| put(b, 16, 120.0)), Reject::OutOfRange), // millimetres sent as metres
        (with(&|b| put(b, 40, 3.0)), Reject::OutOfRange),   // not a unit quaternion
        (with(&|b| put(b, 40, 0.0)), Reject::OutOfRange),
        (good(1, moved).to_vec(), Reject::OutOfOrder),        // a duplicate of seq 1
        (good(0, moved).to_vec(), Reject::OutOfOrder),        // late
        (good(1u32.wrapping_sub(1 << 31), moved).to_vec(), Reject::OutOfOrder), // half the ring back
    ];
    let mut expected = [0u64; 8];
    for (k, (bytes, reason)) in corpus.iter().enumerate() {
        client.send_raw(bytes).unwrap();
        let got = poll_until(&mut bridge, 2 + k as u64);
        assert_eq!(got, None, "packet {k} ({}) was accepted", reason.name());
        expected[Reject::ALL.iter().position(|r| r == reason).unwrap()] += 1;
        for r in Reject::ALL {
            assert_eq!(stats.rejected(r), expected[Reject::ALL.iter().position(|&x| x == r).unwrap()], "after packet {k}: counter {}", r.name());
        }
        let out = core.step(got);
        assert_eq!(out.device, p0.position, "packet {k} moved the tool");
    }
    assert_eq!(stats.dropped(), corpus.len() as u64);
    assert_eq!(stats.accepted.load(std::sync::atomic::Ordering::Relaxed), 1);
    // A good packet after all that still gets through (sequence 2 follows 1).
    let p2 = DeviceInput::at(Vec3::new(0.0, 0.0, 0.01));
    client.send(&p2).unwrap();
    assert_eq!(poll_until(&mut bridge, corpus.len() as u64 + 2), Some(p2));
    // The force goes back to the client.
    core.step(Some(p2));
    bridge.sink().send(&Vec3::new(0.0, 0.0, 1.0));
    let f = client.recv(Duration::from_secs(2)).unwrap().expect("a force packet");
    assert_eq!((f.force, f.ack, f.flags), (Vec3::new(0.0, 0.0, 1.0), 2, 0));
}

const CHILD_ENV: &str = "PALPATE_BRIDGE_CHILD";

/// The second process of `a_second_process_drives_the_loop` (does nothing when run directly).
#[test]
#[ignore = "run by a_second_process_drives_the_loop as its child"]
fn bridge_child_process() {
    let Ok(addr) = std::env::var(CHILD_ENV) else { return };
    let server: SocketAddr = addr.parse().unwrap();
    let mut c = Client::connect(server).unwrap();
    // Press 10 mm down through the plane z = 0 and back, over 0.6 s, a sample a millisecond.
    let (mut n, mut fmax, mut last_ack, mut zeroed) = (0u64, 0.0f64, 0u32, 0u64);
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_millis(600) {
        let t = t0.elapsed().as_secs_f64();
        let z = 0.002 - 0.012 * (1.0 - (2.0 * t / 0.6 - 1.0).abs());
        c.send(&DeviceInput::at(Vec3::new(0.0, 0.0, z))).unwrap();
        while let Some(f) = c.recv(Duration::from_micros(900)).unwrap() {
            n += 1;
            fmax = fmax.max(f.force.z);
            last_ack = f.ack;
            zeroed += (f.flags & 1) as u64;
            if t0.elapsed().as_secs_f64() > t + 0.001 {
                break;
            }
        }
    }
    println!("CHILD forces={n} fmax={fmax} ack={last_ack} zeroed={zeroed}");
}

#[test]
fn a_second_process_drives_the_loop() {
    let bridge = Bridge::localhost(0, DeviceKind::Bridge).unwrap();
    let addr = bridge.local_addr().unwrap();
    let stats = bridge.stats();
    let cfg = ServoConfig { max_ticks: Some(1500), record_ticks: 1500, ..Default::default() };
    let wall = Wall::new(Vec3::zeros(), Vec3::z(), 2000.0, 2.0);
    let core = HapticCore::with_config(Box::new(wall), &cfg, &bridge).unwrap();
    let servo = Servo::start(core, Box::new(bridge), &cfg).unwrap();
    let out = Command::new(std::env::current_exe().unwrap())
        .args(["--ignored", "--exact", "bridge_child_process", "--nocapture", "--test-threads=1"])
        .env(CHILD_ENV, addr.to_string())
        .output()
        .unwrap();
    let report = servo.stop();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "child failed: {text}\n{}", String::from_utf8_lossy(&out.stderr));
    let line = text.lines().find_map(|l| l.find("CHILD").map(|i| &l[i..])).unwrap_or_else(|| panic!("no report from the child: {text}"));
    let field = |k: &str| -> f64 { line.split_whitespace().find_map(|w| w.strip_prefix(&format!("{k}="))).unwrap().parse().unwrap() };
    let accepted = stats.accepted.load(std::sync::atomic::Ordering::Relaxed);
    println!("{line}; bridge accepted {accepted}, dropped {}", stats.dropped());
    assert!(accepted > 100, "the loop took the child's states: {accepted}");
    assert!(field("forces") > 100.0, "the child got forces: {line}");
    assert!(field("fmax") > 0.5, "the child felt the wall: {line}");
    assert!(field("ack") > 100.0, "forces acknowledge the states: {line}");
    assert_eq!(stats.dropped(), 0);
    assert_eq!(field("zeroed"), 0.0, "no fault, no zeroed flag: {line}");
    let rec = report.core.recording().unwrap();
    let zmin = rec.ticks.iter().map(|t| t.input.position.z).fold(f64::INFINITY, f64::min);
    assert!(zmin < -0.005, "the loop saw the press: {zmin}");
}
