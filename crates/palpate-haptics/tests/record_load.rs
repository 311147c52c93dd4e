//! `Recording::load` with what is not a recording file: a FIFO (the read blocked for ever), a
//! directory, and a file over the memory budget (refused from its size, before it is read).

use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;

use palpate_haptics::record::RecordError;
use palpate_haptics::Recording;

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("palpate-record-load-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// `Recording::load(path)` on another thread, with a deadline: a hang fails the test instead of
/// hanging it.
fn load_within(path: &Path, secs: u64) -> Result<Recording, RecordError> {
    let (tx, rx) = mpsc::channel();
    let p = path.to_path_buf();
    std::thread::spawn(move || {
        let _ = tx.send(Recording::load(&p));
    });
    rx.recv_timeout(Duration::from_secs(secs))
        .unwrap_or_else(|_| panic!("Recording::load({}) did not return within {secs} s", path.display()))
}

#[test]
fn a_fifo_is_refused_not_read() {
    let fifo = scratch("rec.fifo");
    let _ = std::fs::remove_file(&fifo);
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    if !matches!(made, Ok(s) if s.success()) {
        eprintln!("skipped: mkfifo is not available");
        return;
    }
    let e = load_within(&fifo, 5).unwrap_err();
    assert!(matches!(e, RecordError::Io { .. }) && e.to_string().contains("not a regular file"), "{e}");
    // Unblock the reader thread of an old build that opened the FIFO (so the test ends).
    let _ = std::fs::OpenOptions::new().write(true).custom_flags_nonblock().open(&fifo);
    let _ = std::fs::remove_file(&fifo);
}

#[test]
fn a_directory_is_refused() {
    let dir = scratch("rec_dir");
    std::fs::create_dir_all(&dir).unwrap();
    let e = load_within(&dir, 5).unwrap_err();
    assert!(e.to_string().contains("a directory"), "{e}");
}

#[test]
fn a_file_over_the_budget_is_refused_before_reading() {
    // 64 GiB, sparse (no disk used): over the default budget of 8 GiB. Read, it would ask for
    // 64 GiB of memory (an abort, or an out-of-memory error after the allocation is tried).
    let big = scratch("rec_big.palprec");
    let f = std::fs::File::create(&big).unwrap();
    if f.set_len(64 << 30).is_err() {
        eprintln!("skipped: the file system cannot hold a sparse 64 GiB file");
        return;
    }
    drop(f);
    let e = load_within(&big, 5).unwrap_err();
    let _ = std::fs::remove_file(&big);
    assert!(matches!(e, RecordError::Limit { .. }), "{e}");
    assert!(e.to_string().contains("PALPATE_MAX_MEMORY"), "{e}");
}

/// Opening a FIFO for writing without blocking (O_NONBLOCK), only to release a blocked reader.
trait NonBlock {
    fn custom_flags_nonblock(&mut self) -> &mut Self;
}

impl NonBlock for std::fs::OpenOptions {
    fn custom_flags_nonblock(&mut self) -> &mut Self {
        use std::os::unix::fs::OpenOptionsExt;
        self.custom_flags(0o4000) // O_NONBLOCK on Linux
    }
}
