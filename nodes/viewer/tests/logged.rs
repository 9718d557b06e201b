//! Known samples through the content and rerun layers into an in-memory sink; the logged
//! chunks are decoded back and their entity paths and component values checked.

use std::collections::BTreeMap;

use teleop_msgs::{
    hand_model, Fingertip, GloveState, HandState, NodeHealth, SampleHeader, Tactile,
};
use teleop_viewer::content::{contact_radius, Scene, SceneConfig, RECORDING_TIME, SAMPLE_TIME};
use teleop_viewer::logger::RerunLogger;
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
        hand_model: hand_model::REVO2,
        joint_count: 6,
        link_up: 1,
        link_errors: 3,
        lost_frames: 1,
        ..Default::default()
    };
    state.joints[2].position = 0.5; // index half closed
    let mut tactile = Tactile {
        header: header(ORIGIN + 2 * MS),
        hand_model: hand_model::REVO2,
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
