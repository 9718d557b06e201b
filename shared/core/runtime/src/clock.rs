//! The pipeline clock.

/// CLOCK_MONOTONIC in nanoseconds: the same clock in every process on the machine, so stamps
/// from different nodes can be subtracted.
pub fn now_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC always exists on Linux.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    debug_assert_eq!(rc, 0);
    (ts.tv_sec as u64)
        .saturating_mul(1_000_000_000)
        .saturating_add(ts.tv_nsec as u64)
}

/// Sleeps until the CLOCK_MONOTONIC time `deadline_ns` (as [`now_ns`]): one absolute-deadline
/// `clock_nanosleep(TIMER_ABSTIME)`, so a late wake-up does not shift the next deadline and
/// nothing spins. Returns at once if the deadline has passed.
pub fn sleep_until_ns(deadline_ns: u64) {
    let ts = libc::timespec {
        tv_sec: (deadline_ns / 1_000_000_000).min(libc::time_t::MAX as u64) as libc::time_t,
        tv_nsec: (deadline_ns % 1_000_000_000) as libc::c_long,
    };
    loop {
        // SAFETY: `ts` is a valid timespec; the remaining-time pointer may be null with
        // TIMER_ABSTIME.
        let rc = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &ts,
                std::ptr::null_mut(),
            )
        };
        // EINTR (a signal): sleep on to the same deadline.
        if rc != libc::EINTR {
            return;
        }
    }
}

/// Sleeps until `t` (an `Instant`, which is CLOCK_MONOTONIC on Linux) with an absolute
/// deadline: see [`sleep_until_ns`]. For control loops and for device simulators' line timing.
pub fn sleep_until(t: std::time::Instant) {
    let left = t.saturating_duration_since(std::time::Instant::now());
    if left.is_zero() {
        return;
    }
    let left_ns = u64::try_from(left.as_nanos()).unwrap_or(u64::MAX);
    sleep_until_ns(now_ns().saturating_add(left_ns));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monotonic() {
        let a = now_ns();
        let b = now_ns();
        assert!(b >= a);
        assert!(a > 0);
    }

    fn thread_cpu_ns() -> u64 {
        let mut ts = libc::timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        // SAFETY: `ts` is a valid, writable timespec.
        unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
        ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
    }

    #[test]
    fn sleeping_does_not_spin() {
        // 100 sleeps of 1 ms: a sleep that spins its last 200 us burns about 20 ms of CPU;
        // a kernel sleep a few microseconds per wake-up.
        let before = thread_cpu_ns();
        let mut deadline = std::time::Instant::now();
        for _ in 0..100 {
            deadline += std::time::Duration::from_millis(1);
            sleep_until(deadline);
        }
        let cpu = thread_cpu_ns() - before;
        assert!(cpu < 10_000_000, "{cpu} ns of CPU in 100 sleeps");
    }

    #[test]
    fn sleeps_to_the_absolute_deadline() {
        let deadline = now_ns() + 3_000_000;
        sleep_until_ns(deadline);
        assert!(now_ns() >= deadline);
        let t = std::time::Instant::now() + std::time::Duration::from_millis(2);
        sleep_until(t);
        assert!(std::time::Instant::now() >= t);
    }
}
