//! Real-time scheduling for the pipeline's threads, as audio software does (JACK's `-R`): a
//! pose frame that waits behind a compiler for the CPU arrives late however fast the code is.

/// Scheduling priority of the sender thread (SCHED_RR; the highest of ours: it keeps time).
pub const SENDER_PRIORITY: i32 = 20;
/// Scheduling priority of the analysis thread (it drains the audio ring).
pub const ANALYSIS_PRIORITY: i32 = 15;
/// Scheduling priority of the motion thread.
pub const MOTION_PRIORITY: i32 = 10;

/// Moves the calling thread to round-robin real-time scheduling at `priority`; returns whether
/// the system allowed it (it needs root, CAP_SYS_NICE or an `rtprio` limit — without them the
/// thread simply stays at normal priority). Round-robin rather than FIFO, and modest priorities,
/// so that a runaway thread still shares the CPU and the kernel's RT throttling applies.
pub fn promote_current_thread(priority: i32) -> bool {
    #[cfg(target_os = "linux")]
    {
        let param = libc::sched_param {
            sched_priority: priority,
        };
        // SAFETY: pthread_self() is always valid for the calling thread; param outlives the call.
        let rc =
            unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_RR, &param) };
        rc == 0
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = priority;
        false
    }
}
