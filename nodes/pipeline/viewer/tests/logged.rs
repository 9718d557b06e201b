//! Known samples through the content and rerun layers into an in-memory sink; the logged
//! chunks are decoded back and their entity paths and component values checked.

use std::collections::BTreeMap;
use std::path::Path;

use teleop_hand_profile::HandProfile;
use teleop_msgs::{
    device_model, units, Fingertip, GloveState, HandState, Message, NodeHealth, SampleHeader,
    Tactile,
};
use teleop_recording::{Filter, RecordedMessage, Recorder, WriterOptions};
use teleop_runtime::Namespace;
use teleop_viewer::content::{contact_radius, Scene, SceneConfig, RECORDING_TIME, SAMPLE_TIME};
use teleop_viewer::logger::RerunLogger;
use teleop_viewer::recording::{view_recording, RecordingSummary};
use teleop_viewer::rerun::components::{Position3D, Radius, Scalar, TensorData};
use teleop_viewer::rerun::datatypes::TensorBuffer;
use teleop_viewer::rerun::log::{Chunk, LogMsg};
use teleop_viewer::rerun::{
    self, BarChart, Points3D, RecordingStreamBuilder, Scalars, TimelineName,
};
use teleop_viewer::sample::Sample;

const MS: u64 = 1_000_000;
const ORIGIN: u64 = 1_000 * MS;

fn header(stamp_ns: u64) -> SampleHeader {
    SampleHeader {
        seq: 1,
        stamp_ns,
        origin_ns: stamp_ns,
        source_id: 1,
        reserved: 0,
    }
}

/// What was logged to the recording store, by entity path (without the leading `/`), plus
/// whether a blueprint store and its activation were sent.
struct Logged {
    chunks: BTreeMap<String, Vec<Chunk>>,
    blueprint_chunks: usize,
    activations: usize,
}

impl Logged {
    fn from(msgs: Vec<LogMsg>) -> Self {
        let mut out = Logged {
            chunks: BTreeMap::new(),
            blueprint_chunks: 0,
            activations: 0,
        };
        for msg in msgs {
            match msg {
                LogMsg::ArrowMsg(store, arrow) => {
                    if store.is_blueprint() {
                        out.blueprint_chunks += 1;
                        continue;
                    }
                    let chunk = Chunk::from_arrow_msg(&arrow).expect("a chunk");
                    let path = chunk.entity_path().to_string();
                    out.chunks
                        .entry(path.trim_start_matches('/').to_string())
                        .or_default()
                        .push(chunk);
                }
                LogMsg::BlueprintActivationCommand(_) => out.activations += 1,
                LogMsg::SetStoreInfo(_) => {}
            }
        }
        out
    }

    fn chunks(&self, path: &str) -> &[Chunk] {
        self.chunks
            .get(path)
            .map(Vec::as_slice)
            .unwrap_or_else(|| panic!("nothing logged at {path}; logged: {:?}", self.chunks.keys()))
    }

    /// Every row's values of a component at `path`, in logging order.
    fn rows<C: rerun::Component + Clone>(
        &self,
        path: &str,
        component: rerun::ComponentIdentifier,
    ) -> Vec<Vec<C>> {
        self.chunks(path)
            .iter()
            .flat_map(|c| {
                c.iter_component::<C>(component)
                    .map(|item| item.to_vec())
                    .collect::<Vec<_>>()
            })
            .filter(|row| !row.is_empty())
            .collect()
    }

    fn scalars(&self, path: &str) -> Vec<f64> {
        self.rows::<Scalar>(path, Scalars::descriptor_scalars().component)
            .into_iter()
            .map(|row| row[0].0 .0)
            .collect()
    }

    fn positions(&self, path: &str) -> Vec<Vec<[f32; 3]>> {
        self.rows::<Position3D>(path, Points3D::descriptor_positions().component)
            .into_iter()
            .map(|row| row.into_iter().map(|p| p.0 .0).collect())
            .collect()
    }

    /// The times of the rows at `path` on `timeline`.
    fn times(&self, path: &str, timeline: &'static str) -> Vec<i64> {
        let name = TimelineName::from(timeline);
        self.chunks(path)
            .iter()
            .flat_map(|c| {
                c.timelines()
                    .get(&name)
                    .map(|t| t.times_raw().to_vec())
                    .unwrap_or_default()
            })
            .collect()
    }
}

fn log_samples(samples: &[(Sample, u64)]) -> (Logged, Scene) {
    let (rec, storage) = RecordingStreamBuilder::new("teleop_viewer_test")
        .memory()
        .expect("memory sink");
    let logger = RerunLogger::new(rec.clone());
    let mut scene = Scene::new(
        SceneConfig {
            time_origin_ns: ORIGIN,
            ..SceneConfig::default()
        },
        None,
    );
    logger.log_scene(&scene).expect("static and layout");
    for (sample, received) in samples {
        if let Some(frame) = scene.frame(sample, *received) {
            logger.log_frame(&frame).expect("log");
        }
    }
    rec.flush_blocking().expect("flush");
    (Logged::from(storage.take()), scene)
}

#[test]
fn glove_state_logs_the_operator_hand_and_closures() {
    let mut glove = GloveState {
        header: header(ORIGIN + 10 * MS),
        link_up: 1,
        errors: 2,
        ..Default::default()
    };
    // little, ring, middle, index, thumb (1 = open), thumb rotation (1 = outermost)
    glove.position = [1.0, 1.0, 0.5, 0.0, 1.0, 1.0];
    let (logged, scene) = log_samples(&[(Sample::GloveState(glove), ORIGIN + 12 * MS)]);

    // The fingertips are where the kinematic model puts them.
    let tips = logged.positions("hands/operator/tips");
    let expected: Vec<[f32; 3]> = scene
        .operator_pose(&glove.position)
        .tips()
        .into_iter()
        .map(|v| v.to_array())
        .collect();
    assert_eq!(tips, vec![expected]);
    // Open little finger: straight out along +Y from its knuckle; the bent index is curled.
    let little = scene.operator_model().fingers[3];
    let length: f32 = little.lengths.iter().sum();
    let straight = little.base + glam::Vec3::Y * length;
    assert!((glam::Vec3::from(tips[0][4]) - straight).length() < 1e-5);
    assert!(tips[0][1][2] < scene.operator_model().fingers[0].base.z - 0.02);

    // 5 fingers + the palm: 11 strips; joints: wrist + 5 x 4.
    let joints = logged.positions("hands/operator/joints");
    assert_eq!(joints[0].len(), 21);

    assert_eq!(logged.scalars("glove/position/index"), vec![1.0]);
    assert_eq!(logged.scalars("glove/position/middle"), vec![0.5]);
    assert_eq!(logged.scalars("glove/position/little"), vec![0.0]);
    assert_eq!(logged.scalars("glove/position/thumb_rotation"), vec![0.0]);
    assert_eq!(logged.scalars("health/glove/errors"), vec![2.0]);
    assert_eq!(logged.scalars("latency/delivery/glove_state"), vec![2.0]);

    // Both timelines, from the origin.
    assert_eq!(
        logged.times("glove/position/index", RECORDING_TIME),
        vec![(12 * MS) as i64]
    );
    assert_eq!(
        logged.times("glove/position/index", SAMPLE_TIME),
        vec![(10 * MS) as i64]
    );

    // The static placement and coordinate convention, and the default layout.
    assert!(logged.chunks("hands").iter().all(Chunk::is_static));
    assert!(logged.chunks("hands/operator").iter().all(Chunk::is_static));
    assert!(logged.blueprint_chunks > 0, "the default layout is sent");
    assert_eq!(logged.activations, 1);
}

#[test]
fn tactile_logs_bars_and_contacts_scaled_by_force() {
    let mut state = HandState {
        header: header(ORIGIN + MS),
        hand_model: device_model::REVO2,
        joint_count: 6,
        link_up: 1,
        link_errors: 3,
        lost_frames: 1,
        ..Default::default()
    };
    state.joints[2].position = 0.5; // index half closed
    let mut tactile = Tactile {
        header: header(ORIGIN + 2 * MS),
        hand_model: device_model::REVO2,
        fingertip_count: 5,
        ..Default::default()
    };
    tactile.fingertips[1] = Fingertip {
        normal_n: 3.0,
        tangential_n: 1.5,
        direction_deg: 90.0,
        direction_valid: 1,
        ..Default::default()
    };
    tactile.fingertips[3].normal_n = 0.5;
    let (logged, scene) = log_samples(&[
        (Sample::HandState(state), ORIGIN + MS),
        (Sample::Tactile(tactile), ORIGIN + 2 * MS),
    ]);

    // Bar chart of the current normal forces, thumb .. little.
    let bars = logged.rows::<TensorData>("bars/tactile", BarChart::descriptor_values().component);
    assert_eq!(bars.len(), 1);
    let TensorBuffer::F32(values) = &bars[0][0].0.buffer else {
        panic!("f32 bars expected");
    };
    assert_eq!(values.to_vec(), vec![0.0, 3.0, 0.0, 0.5, 0.0]);
    assert_eq!(logged.scalars("robot/index/tactile/normal_n"), vec![3.0]);

    // The first hand sample picked the Revo2's profile: its layout was sent after the first.
    assert_eq!(logged.activations, 2);
    let robot = scene.robot_model().expect("the Revo2 profile");
    assert_eq!(robot.profile().name, "revo2");
    // Contacts at the posed robot fingertips, radius from the force.
    let half_index: Vec<f32> = robot
        .profile()
        .joints
        .iter()
        .zip([0.0, 0.0, 0.5, 0.0, 0.0, 0.0])
        .map(|(j, q)| j.radians(q))
        .collect();
    let posed = robot.pose(&half_index).tips();
    assert_eq!(
        logged.positions("hands/robot/contacts"),
        vec![vec![posed[1].to_array(), posed[3].to_array()]]
    );
    let radii: Vec<f32> = logged.rows::<Radius>(
        "hands/robot/contacts",
        Points3D::descriptor_radii().component,
    )[0]
    .iter()
    .map(|r| r.0 .0)
    .collect();
    assert_eq!(radii, vec![contact_radius(3.0), contact_radius(0.5)]);
    assert!((radii[0] - (0.007 + 3.0 * 0.003)).abs() < 1e-6, "{radii:?}");
    assert!(radii[0] > radii[1], "larger force, larger sphere");
    // One tangential arrow, from the index tip.
    let origins = logged.rows::<Position3D>(
        "hands/robot/tangential",
        rerun::Arrows3D::descriptor_origins().component,
    );
    assert_eq!(origins, vec![vec![Position3D::from(posed[1].to_array())]]);

    // Link health of the hand and its measured joints.
    assert_eq!(logged.scalars("health/hand/link_errors"), vec![3.0]);
    assert_eq!(logged.scalars("health/hand/lost_frames"), vec![1.0]);
    assert_eq!(logged.scalars("robot/index/index/measured"), vec![0.5]);
}

#[test]
fn health_logs_counters_per_node() {
    let mut h = NodeHealth {
        header: header(ORIGIN + 5 * MS),
        timeouts: 4,
        errors: 1,
        dropped: 17,
        ..Default::default()
    };
    h.set_name("retarget");
    let mut later = h;
    later.header.stamp_ns += 500 * MS;
    later.dropped = 20;
    let (logged, _) = log_samples(&[
        (Sample::Health(h), ORIGIN + 5 * MS),
        (Sample::Health(later), ORIGIN + 505 * MS),
    ]);
    assert_eq!(
        logged.scalars("health/nodes/retarget/timeouts"),
        vec![4.0, 4.0]
    );
    assert_eq!(
        logged.scalars("health/nodes/retarget/errors"),
        vec![1.0, 1.0]
    );
    assert_eq!(
        logged.scalars("health/nodes/retarget/dropped"),
        vec![17.0, 20.0]
    );
}

/// Writes hand states to `path`, each on its channel (`hand/state` or `NS/hand/state`).
fn write_recording(
    path: &Path,
    metadata: &[(String, BTreeMap<String, String>)],
    states: &[(&str, HandState)],
) {
    let mut rec = Recorder::create(path, WriterOptions::default(), metadata).expect("create");
    for (i, (channel, state)) in states.iter().enumerate() {
        let id = rec
            .add_topic(channel, HandState::SCHEMA_NAME, &HandState::schema())
            .expect("topic");
        let msg = RecordedMessage {
            topic: channel,
            ..RecordedMessage::from_sample(state, ORIGIN + i as u64 * MS)
        };
        rec.write(id, &msg).expect("write");
    }
    rec.finish().expect("finish");
}

/// The recording at `path` through the recording source into memory.
fn view(path: &Path, namespace: Option<&str>) -> anyhow::Result<(RecordingSummary, Logged)> {
    let (rec, storage) = RecordingStreamBuilder::new("teleop_viewer_test")
        .memory()
        .expect("memory sink");
    let namespace = namespace.map(|n| Namespace::new(n).expect("a namespace"));
    let summary = view_recording(
        path,
        &Filter::all(),
        namespace.as_ref(),
        &RerunLogger::new(rec.clone()),
        SceneConfig::default(),
        None,
        false,
    )?;
    rec.flush_blocking().expect("flush");
    Ok((summary, Logged::from(storage.take())))
}

fn hand_state(model: u8, joints: u8, unit: u8, index_position: (usize, f32)) -> HandState {
    let mut state = HandState {
        header: header(ORIGIN),
        hand_model: model,
        joint_count: joints,
        units: unit,
        ..Default::default()
    };
    state.joints[index_position.0].position = index_position.1;
    state
}

const ALLEGRO_TOML: &str = include_str!("../../../../config/hands/allegro.toml");

fn profile_metadata(text: &str) -> Vec<(String, BTreeMap<String, String>)> {
    vec![(
        "hand_profile".to_string(),
        BTreeMap::from([
            ("file".to_string(), "config/hands/allegro.toml".to_string()),
            ("text".to_string(), text.to_string()),
        ]),
    )]
}

#[test]
fn a_recording_is_drawn_with_its_profile_in_its_namespace() {
    let dir = tempfile::tempdir().unwrap();
    let allegro = HandProfile::builtin("allegro").unwrap();
    let index_1 = allegro.joint_index("index_1").unwrap();
    let states = [
        (
            "left/hand/state",
            hand_state(device_model::ALLEGRO, 16, units::PHYSICAL, (index_1, 0.4)),
        ),
        (
            "hand/state",
            hand_state(device_model::REVO2, 6, units::NORMALISED, (2, 0.5)),
        ),
    ];

    // The profile the recorder embedded, the channels of `left` only.
    let with_profile = dir.path().join("left.mcap");
    write_recording(&with_profile, &profile_metadata(ALLEGRO_TOML), &states);
    let (summary, logged) = view(&with_profile, Some("left")).unwrap();
    assert_eq!((summary.messages, summary.skipped), (2, 1), "{summary:?}");
    let q = logged.scalars("robot/index/index_1/measured");
    assert_eq!(q.len(), 1);
    assert!((q[0] - f64::from(allegro.joints[index_1].normalised(0.4))).abs() < 1e-6);
    assert!(!logged.chunks.contains_key("robot/index/index/measured"));
    assert!(logged
        .chunks("devices/hand_profile")
        .iter()
        .all(Chunk::is_static));

    // No profile embedded: the builtin profile of the first hand sample's model, here the
    // Revo2 outside any namespace.
    let without = dir.path().join("root.mcap");
    write_recording(&without, &[], &states);
    let (summary, logged) = view(&without, None).unwrap();
    assert_eq!((summary.messages, summary.skipped), (2, 1), "{summary:?}");
    assert_eq!(logged.scalars("robot/index/index/measured"), vec![0.5]);
    assert_eq!(
        logged.activations, 2,
        "a layout before, and one for the Revo2"
    );

    // A namespace the recording does not have: refused, naming those it has.
    let Err(e) = view(&without, Some("right")) else {
        panic!("a missing namespace was accepted");
    };
    let text = e.to_string();
    assert!(
        text.contains(
            "no channels in namespace `right`; its namespaces: none (no --namespace), `left`"
        ),
        "{text}"
    );
}

#[test]
fn a_recording_whose_profile_does_not_load_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("broken.mcap");
    let broken = ALLEGRO_TOML.replacen("limits = [-0.47, 0.47]", "limits = [0.47, -0.47]", 1);
    assert_ne!(broken, ALLEGRO_TOML);
    write_recording(&path, &profile_metadata(&broken), &[]);
    let Err(e) = view(&path, None) else {
        panic!("a broken profile was accepted");
    };
    let text = format!("{e:#}");
    assert!(
        text.contains("metadata hand_profile, from config/hands/allegro.toml):")
            && text.contains("joint[0].limits")
            && text.contains("--profile"),
        "{text}"
    );
}
