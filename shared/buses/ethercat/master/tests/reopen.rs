//! A bus opened and dropped again and again (a flapping link, a node bringing its bus up anew)
//! frees its PDU storage each time: memory stays flat. Alone in its test binary, so that the
//! process-wide count of live storages is this test's.
#![allow(clippy::unwrap_used, missing_docs)]

use std::sync::{Arc, Mutex};
use std::time::Instant;

use futures_lite::future::block_on;
use teleop_ecat_link::{FrameLink, InProcessLink};
use teleop_ecat_master::{scan, Bus};
use teleop_ecat_sim::{Application, EscConfig, SubDevice};

/// A SubDevice without objects or process data.
struct Bare;

impl Application for Bare {
    teleop_ecat_sim::no_objects!();
}

#[test]
fn two_hundred_reopened_buses_leave_one_pdu_storage() {
    let sim = Arc::new(Mutex::new(SubDevice::new(EscConfig::default(), Bare)));
    let start = Instant::now();
    assert_eq!(Bus::live_storages(), 0);
    for reopen in 0..200 {
        let sim = sim.clone();
        let bus = Bus::open(Box::new(move || {
            let sim = sim.clone();
            Ok(Box::new(InProcessLink::new(move |frame: &[u8]| {
                sim.lock().unwrap().process_frame(frame, start.elapsed())
            })) as Box<dyn FrameLink>)
        }))
        .unwrap();
        assert_eq!(Bus::live_storages(), 1, "reopen {reopen}");
        if reopen % 50 == 0 {
            // The bus works: frames go through its storage.
            let (group, found) = block_on(scan(bus.md())).unwrap();
            assert_eq!((group.len(), found.len()), (1, 1));
        }
    }
    assert_eq!(Bus::live_storages(), 0, "every storage freed with its bus");
}
