//! Real-time scheduling for the servo thread (opt-in: [`crate::ServoConfig::realtime`]).
//!
//! Under Linux's default scheduler a busy machine preempts the servo for milliseconds: the tick
//! then ends late (an overrun) although its own compute fit in the period. A haptic application
//! runs its servo under `SCHED_FIFO`, a fixed priority above every ordinary thread, so that only
//! the kernel and other real-time threads can preempt it. That needs privilege (root, or
//! `CAP_SYS_NICE`, or an `rtprio` limit in `/etc/security/limits.conf`); without it the request is
//! refused and the loop runs as before, saying why. The kernel's real-time throttling (by default
//! 95% of each second, `/proc/sys/kernel/sched_rt_runtime_us`) keeps a runaway servo from
//! freezing the machine; it also means that a real-time servo must sleep, not spin, through the
//! rest of its tick ([`crate::ServoConfig::spin`] 0): measured on the Rodero ventricle at 1 kHz
//! (compute ~0.8 ms a tick on a loaded 2-core machine), spinning the last 200 us made the thread
//! use the whole core, and the throttle then took it off the CPU for ~50 ms a second (period
//! max 54 ms, 4 watchdog trips in 8 s); sleeping, the period's max was 4.5 ms and no trip. And
//! when the physics itself takes longer than the period, a real-time servo never sleeps: it rests
//! 6% of the period every tick regardless (measured before that rest: 60 s on Rodero at 1 kHz,
//! whose deep presses take 1.0-1.4 ms a tick, gave a 53 ms stall and a watchdog trip; at 2 and
//! 4 kHz 4 and 10 trips in 10 s).
//!
//! The watchdog, which must run when the servo is stuck, gets one priority level above the servo.
//!
//! Without privilege, an ordinary servo thread asks for what Linux gives anyone: the shortest
//! time slice of its EEVDF scheduler ([`request_short_slice`], kernels 6.12 and later), so that
//! it preempts a CPU-bound program as soon as it wakes, and a 1 us timer slack
//! ([`set_timer_slack`]), so that its sleeps end on time. The multirate servo, whose work is
//! ~10-20 us a period, then sleeps to each deadline: beside a CPU-bound program it was late 40-48
//! times in 30 s at 1 and 4 kHz (Rodero, 2-core VM, 2026-12-06), where sleeping all but the last
//! 200 us of each wait gave 593 and 6,329 (a thread that spins uses up its share of the CPU and
//! loses the scheduler's preference on waking).

/// The servo's `SCHED_FIFO` priority (1-99): above ordinary threads and the default of most
/// audio and IRQ threads (50), below the kernel's own watchdogs (99).
pub const SERVO_PRIORITY: i32 = 80;

/// What became of a request for real-time scheduling.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Realtime {
    /// Not asked for ([`crate::ServoConfig::realtime`] false).
    Off,
    /// The thread runs under `SCHED_FIFO` at this priority.
    Granted(i32),
    /// Asked for and refused: the reason (e.g. no privilege), the thread runs as before.
    Refused(String),
}

impl Realtime {
    pub fn granted(&self) -> bool {
        matches!(self, Realtime::Granted(_))
    }
}

/// Puts the calling thread under `SCHED_FIFO` at `priority`.
#[cfg(target_os = "linux")]
pub fn make_current_thread_realtime(priority: i32) -> Realtime {
    let param = libc::sched_param { sched_priority: priority };
    // SAFETY: `pthread_self` is the calling thread, alive; `param` is a valid sched_param that
    // outlives the call.
    let rc = unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) };
    if rc == 0 {
        Realtime::Granted(priority)
    } else {
        let why = std::io::Error::from_raw_os_error(rc);
        Realtime::Refused(format!("SCHED_FIFO priority {priority} refused: {why} (needs root, CAP_SYS_NICE or an rtprio limit)"))
    }
}

/// Not on this platform: refused.
#[cfg(not(target_os = "linux"))]
pub fn make_current_thread_realtime(priority: i32) -> Realtime {
    Realtime::Refused(format!("SCHED_FIFO priority {priority}: real-time scheduling is implemented for Linux only"))
}

/// The calling thread's scheduling policy is `SCHED_FIFO` (tests and reports).
#[cfg(target_os = "linux")]
pub fn current_thread_is_fifo() -> bool {
    let mut policy = 0;
    let mut param = libc::sched_param { sched_priority: 0 };
    // SAFETY: valid out-pointers for the calling thread.
    let rc = unsafe { libc::pthread_getschedparam(libc::pthread_self(), &mut policy, &mut param) };
    rc == 0 && policy == libc::SCHED_FIFO
}

#[cfg(not(target_os = "linux"))]
pub fn current_thread_is_fifo() -> bool {
    false
}

/// The calling thread's CPU time \[s\] (`CLOCK_THREAD_CPUTIME_ID`): the time it ran, without the
/// time it waited while the machine ran something else. The servo reads it around each tick's
/// compute to tell an overrun of the physics' own work (its CPU time longer than the period)
/// from one of the machine's (the thread off the CPU mid-tick, or woken late). `None` where the
/// clock is unavailable.
#[cfg(unix)]
pub fn thread_cpu_time() -> Option<f64> {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: a valid out-pointer; the clock id is a constant of the platform.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    (rc == 0).then_some(ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9)
}

#[cfg(not(unix))]
pub fn thread_cpu_time() -> Option<f64> {
    None
}

/// The slice an ordinary servo thread asks of the scheduler \[ns\]: the least Linux grants
/// (0.1 ms; the default is 0.7-3 ms).
pub const SERVO_SLICE_NS: u64 = 100_000;

/// Asks the scheduler for a short time slice for the calling ordinary (`SCHED_OTHER`) thread:
/// under Linux's EEVDF scheduler (6.12 and later) a task with a shorter slice gets an earlier
/// virtual deadline, so when it wakes it preempts a CPU-bound program at once instead of waiting
/// for that program's slice to end. It needs no privilege (it asks for no more CPU, only for it
/// sooner and in shorter pieces). Returns whether the kernel took it; older kernels and other
/// platforms refuse, and the thread runs as before.
#[cfg(target_os = "linux")]
pub fn request_short_slice(slice_ns: u64) -> bool {
    /// `struct sched_attr` of `sched_setattr(2)`, its first version (48 bytes).
    #[repr(C)]
    struct SchedAttr {
        size: u32,
        policy: u32,
        flags: u64,
        nice: i32,
        priority: u32,
        runtime: u64,
        deadline: u64,
        period: u64,
    }
    // SAFETY: gettid takes no argument.
    let tid = unsafe { libc::syscall(libc::SYS_gettid) } as libc::id_t;
    // The thread's own nice value, kept (errno is not needed: a nice of -1 is as good as any).
    // SAFETY: getpriority on the calling thread's id reads no memory of ours.
    let nice = unsafe { libc::getpriority(libc::PRIO_PROCESS, tid) };
    let attr = SchedAttr {
        size: std::mem::size_of::<SchedAttr>() as u32,
        policy: libc::SCHED_OTHER as u32,
        flags: 0,
        nice,
        priority: 0,
        runtime: slice_ns,
        deadline: 0,
        period: 0,
    };
    // SAFETY: `attr` is a valid sched_attr of the size it declares, alive for the call; pid 0 is
    // the calling thread.
    let rc = unsafe { libc::syscall(libc::SYS_sched_setattr, 0, &attr as *const SchedAttr, 0u32) };
    rc == 0
}

#[cfg(not(target_os = "linux"))]
pub fn request_short_slice(_slice_ns: u64) -> bool {
    false
}

/// The timer slack the servo thread asks for \[ns\] (Linux's default for an ordinary thread is
/// 50 us: a sleep may end that much after its deadline).
pub const SERVO_TIMER_SLACK_NS: u64 = 1_000;

/// Sets the calling thread's timer slack (`PR_SET_TIMERSLACK`): how late the kernel may end its
/// sleeps to group wake-ups. No privilege needed. Returns whether the kernel took it.
#[cfg(target_os = "linux")]
pub fn set_timer_slack(slack_ns: u64) -> bool {
    // SAFETY: prctl with PR_SET_TIMERSLACK takes an integer argument and touches no memory.
    unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, slack_ns as libc::c_ulong, 0, 0, 0) == 0 }
}

#[cfg(not(target_os = "linux"))]
pub fn set_timer_slack(_slack_ns: u64) -> bool {
    false
}
