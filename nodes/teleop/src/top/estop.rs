//! The console's e-stop actions, in order: an engage writes its latches at once, on the key's
//! thread (they alone stop every node), and everything that waits (ringing the doorbells,
//! a release, the acknowledgements) runs on one worker thread, one action after the other. A
//! release asked for before an engage never undoes it: it carries the count of engages asked for
//! when it was asked for, and gives up when the count moved ([`inspect::release`]).
//!
//! [`inspect::release`]: crate::inspect::release

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{channel, Sender};
use std::sync::Arc;

use teleop_runtime::{IpcSettings, Namespace};

use super::Done;
use crate::inspect::{self, EngageRequests, Latched, ReleaseAbandoned};

/// One action for the worker.
enum Job {
    /// Ring the doorbells of an engage whose latches are written.
    Ring(Latched),
    /// Release, asked for when [`EngageRequests::count`] was this.
    Release { since: u64 },
}

/// The e-stop's worker thread, seen from the console's loop.
pub struct EStopWorker {
    jobs: Sender<Job>,
    requests: Arc<EngageRequests>,
    /// A doorbell is queued and not yet being rung: a key held down (or pressed again) writes
    /// the latches again but does not queue another.
    ring_queued: Arc<AtomicBool>,
    ipc: IpcSettings,
    given: Vec<Namespace>,
}

/// What [`EStopWorker::engage`] did at once.
pub struct Engaged {
    /// The latches written, or what could not be written, in a line.
    pub message: String,
    /// The doorbell was queued (a [`Done`] follows).
    pub queued: bool,
}

impl EStopWorker {
    /// Starts the worker for the namespaces `given` (or every side); it tells `done` what each
    /// action did, and ends when the worker is dropped (after the actions queued).
    pub fn start(
        ipc: &IpcSettings,
        given: &[Namespace],
        done: Sender<Done>,
    ) -> std::io::Result<Self> {
        let (jobs, queue) = channel::<Job>();
        let requests = Arc::new(EngageRequests::default());
        let ring_queued = Arc::new(AtomicBool::new(false));
        {
            let (ipc, given) = (ipc.clone(), given.to_vec());
            let (requests, ring_queued) = (requests.clone(), ring_queued.clone());
            std::thread::Builder::new()
                .name("top-estop".into())
                .spawn(move || {
                    for job in queue {
                        let message = match job {
                            Job::Ring(latched) => {
                                ring_queued.store(false, Ordering::SeqCst);
                                estop_message(
                                    "engage",
                                    Ok(inspect::ring_engaged(&ipc, &given, latched)),
                                )
                            }
                            Job::Release { since } => estop_message(
                                "release",
                                inspect::release(&ipc, &given, &requests, since),
                            ),
                        };
                        // The console may have quit meanwhile: nobody to tell.
                        let _ = done.send(Done {
                            estop: true,
                            message,
                        });
                    }
                })?;
        }
        Ok(Self {
            jobs,
            requests,
            ring_queued,
            ipc: ipc.clone(),
            given: given.to_vec(),
        })
    }

    /// Engages now: counts the engage (a release under way or queued gives up), writes the
    /// latches on this thread, and queues the doorbells unless some are queued already.
    pub fn engage(&self) -> Engaged {
        let latched = self.requests.engage(&self.ipc, &self.given);
        let mut message = if latched.failures.is_empty() {
            "e-stop latched".to_string()
        } else {
            format!("e-stop latch FAILED: {}", latched.failures.join("; "))
        };
        let queued = !self.ring_queued.swap(true, Ordering::SeqCst);
        if queued && self.jobs.send(Job::Ring(latched)).is_err() {
            message.push_str("; the doorbells cannot be rung (the e-stop's worker ended)");
            return Engaged {
                message,
                queued: false,
            };
        }
        message.push_str("; ringing the doorbells");
        Engaged { message, queued }
    }

    /// Queues a release; false when the worker ended (nothing will be done).
    pub fn release(&self) -> bool {
        let since = self.requests.count();
        self.jobs.send(Job::Release { since }).is_ok()
    }
}

/// What an e-stop engage or release (`action`) did, in one line: `teleop estop`'s headline, who
/// acknowledged, and what went wrong.
pub fn estop_message(action: &str, report: anyhow::Result<inspect::EStopReport>) -> String {
    match report {
        Err(e) if e.downcast_ref::<ReleaseAbandoned>().is_some() => {
            format!("e-stop {action} abandoned: {e:#}")
        }
        Err(e) => format!("e-stop {action} FAILED: {e:#}"),
        Ok(report) => {
            // The headline's state, without its explanation (the screen shows the rest).
            let state = report.headline().split(':').next().unwrap_or_default();
            let mut text = state.to_string();
            for line in report.ack_lines() {
                text.push_str(&format!("; {line}"));
            }
            if let Some(problem) = report.problem() {
                text.push_str(&format!("; {}", problem.replace('\n', " ")));
            }
            text
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use std::time::{Duration, Instant};

    use super::*;
    use teleop_runtime::latch_path;

    #[test]
    fn a_failure_names_its_action() {
        let failed = || Err(anyhow::anyhow!("no room"));
        assert_eq!(
            estop_message("engage", failed()),
            "e-stop engage FAILED: no room"
        );
        assert_eq!(
            estop_message("release", failed()),
            "e-stop release FAILED: no room"
        );
        let abandoned = estop_message("release", Err(ReleaseAbandoned { removed: 0 }.into()));
        assert!(abandoned.starts_with("e-stop release abandoned: the e-stop was engaged after"));
    }

    #[test]
    fn a_release_asked_before_an_engage_never_undoes_it() {
        let dir = tempfile::tempdir().unwrap();
        let ipc = IpcSettings::isolated(dir.path());
        let latch = latch_path(&ipc, None);
        let requests = EngageRequests::default();
        requests.engage(&ipc, &[]);
        assert!(latch.exists());
        // Asked for now, run after the next engage (behind it on the worker, or still
        // creating its node when the key was pressed).
        let since = requests.count();
        requests.engage(&ipc, &[]);
        let e = inspect::release(&ipc, &[], &requests, since).unwrap_err();
        assert_eq!(
            e.downcast_ref::<ReleaseAbandoned>(),
            Some(&ReleaseAbandoned { removed: 0 })
        );
        assert!(latch.exists(), "the engage's latch was removed");
        // With no engage since, the release goes through.
        let report = inspect::release(&ipc, &[], &requests, requests.count()).unwrap();
        assert_eq!(report.latches, vec![latch.clone()]);
        assert!(!latch.exists());
        ipc.remove_shared_memory();
    }

    #[test]
    fn the_worker_runs_the_actions_in_order_and_engages_at_once() {
        let dir = tempfile::tempdir().unwrap();
        let ipc = IpcSettings::isolated(dir.path());
        let latch = latch_path(&ipc, None);
        let (done_tx, done) = channel();
        let worker = EStopWorker::start(&ipc, &[], done_tx).unwrap();
        let engaged = worker.engage();
        // Written on this thread, before the worker did anything.
        assert!(latch.exists(), "{}", engaged.message);
        assert!(engaged.queued);
        // A release, then an engage right behind it: the release gives up, the latch stays.
        assert!(worker.release());
        let again = worker.engage();
        assert!(latch.exists());
        let expected = 1 + 1 + usize::from(again.queued);
        let mut said = Vec::new();
        let deadline = Instant::now() + Duration::from_secs(30);
        while said.len() < expected && Instant::now() < deadline {
            if let Ok(d) = done.recv_timeout(Duration::from_millis(100)) {
                said.push(d.message);
            }
        }
        assert_eq!(said.len(), expected, "{said:?}");
        assert!(said[0].starts_with("e-stop ENGAGED"), "{said:?}");
        assert!(said[1].starts_with("e-stop release abandoned"), "{said:?}");
        assert!(latch.exists(), "{said:?}");
        drop(worker);
        ipc.remove_shared_memory();
    }
}
