//! The live source end to end in one process: publishers on an isolated iceoryx2 prefix (in
//! the namespace `left` and outside it), the viewer's subscriber and logging threads in `left`,
//! and an in-memory rerun sink.

use std::time::Duration;

use teleop_msgs::{device_model, HandState};
use teleop_runtime::{IpcSettings, NodeRuntime};
use teleop_viewer::content::SAMPLE_TIME;
use teleop_viewer::live::{run_live, LiveOptions};
use teleop_viewer::logger::RerunLogger;
use teleop_viewer::rerun::components::Scalar;
use teleop_viewer::rerun::log::{Chunk, LogMsg};
use teleop_viewer::rerun::{RecordingStreamBuilder, Scalars, TimelineName};

/// The chunks logged to the recording at `path`.
fn chunks<'a>(msgs: &'a [LogMsg], path: &'a str) -> impl Iterator<Item = Chunk> + 'a {
    msgs.iter().filter_map(move |msg| {
        let LogMsg::ArrowMsg(store, arrow) = msg else {
            return None;
        };
        let chunk = Chunk::from_arrow_msg(arrow).expect("a chunk");
        (store.is_recording() && chunk.entity_path().to_string().trim_start_matches('/') == path)
            .then_some(chunk)
    })
}

fn scalars(msgs: &[LogMsg], path: &str) -> Vec<f64> {
    chunks(msgs, path)
        .flat_map(|c| {
            c.iter_component::<Scalar>(Scalars::descriptor_scalars().component)
                .flat_map(|row| row.iter().map(|s| s.0 .0).collect::<Vec<_>>())
                .collect::<Vec<_>>()
        })
        .collect()
}

fn sample_times(msgs: &[LogMsg], path: &str) -> Vec<i64> {
    let timeline = TimelineName::from(SAMPLE_TIME);
    chunks(msgs, path)
        .flat_map(|c| {
            c.timelines()
                .get(&timeline)
                .map(|t| t.times_raw().to_vec())
                .unwrap_or_default()
        })
        .collect()
}

#[test]
fn live_samples_are_decimated_and_logged() {
    let dir = tempfile::tempdir().unwrap();
    let settings = IpcSettings::isolated(dir.path());
    let (rec, storage) = RecordingStreamBuilder::new("teleop_viewer_live_test")
        .memory()
        .unwrap();
    let logger = RerunLogger::new(rec.clone());
    let viewer_settings = IpcSettings {
        namespace: Some("left".into()),
        ..settings.clone()
    };
    let hand_settings = viewer_settings.clone();
    let viewer = std::thread::spawn(move || {
        let runtime = NodeRuntime::new("viewer", &viewer_settings).unwrap();
        let options = LiveOptions {
            duration: Some(Duration::from_secs(3)),
            ..LiveOptions::default()
        };
        run_live(&runtime, logger, &options, None).unwrap()
    });

    let runtime = NodeRuntime::new("test-hand", &hand_settings).unwrap();
    let mut publisher = runtime.publisher::<HandState>().unwrap();
    // The same topic outside the namespace: not viewed.
    let other_runtime = NodeRuntime::new("other-hand", &settings).unwrap();
    let mut other = other_runtime.publisher::<HandState>().unwrap();
    std::thread::sleep(Duration::from_millis(500)); // the viewer subscribes meanwhile
    let mut state = HandState {
        hand_model: device_model::REVO2,
        joint_count: 6,
        link_up: 1,
        ..Default::default()
    };
    state.joints[2].position = 0.25;
    let mut outside = state;
    outside.joints[2].position = 0.75;
    for i in 0..300 {
        state.link_errors = i;
        publisher.publish(&state).unwrap();
        other.publish(&outside).unwrap();
        std::thread::sleep(Duration::from_millis(1));
    }
    let summary = viewer.join().unwrap();
    drop((publisher, other));
    drop((runtime, other_runtime));
    settings.remove_shared_memory();

    // ~1 kHz thinned to <= 100 Hz by the samples' stamps; nothing dropped.
    assert!(
        summary.forwarded >= 2 && summary.decimated > 0,
        "{summary:?}"
    );
    // The 300 samples in `left`; the 300 outside it are not subscribed.
    assert_eq!(summary.forwarded + summary.decimated, 300, "{summary:?}");
    assert_eq!((summary.queue_full, summary.missed), (0, 0), "{summary:?}");
    assert_eq!(summary.frames, summary.forwarded);

    let msgs = storage.take();
    let index = scalars(&msgs, "robot/index/index/measured");
    assert_eq!(index.len() as u64, summary.forwarded);
    assert!(index.iter().all(|v| *v == 0.25));
    let times = sample_times(&msgs, "health/hand/link_errors");
    assert_eq!(times.len() as u64, summary.forwarded);
    assert!(
        times.windows(2).all(|w| w[1] - w[0] >= 10_000_000),
        "at most one sample per 10 ms of sample time: {times:?}"
    );
    let wkc = scalars(&msgs, "health/hand/link_errors");
    assert!(wkc.windows(2).all(|w| w[1] > w[0]), "{wkc:?}");
    // The viewer's own drop counters are logged too.
    assert!(scalars(&msgs, "health/viewer/queue_full")
        .iter()
        .all(|v| *v == 0.0));
    assert!(!scalars(&msgs, "health/viewer/missed").is_empty());
}
