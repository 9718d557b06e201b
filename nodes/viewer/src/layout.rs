//! The default layout (a rerun blueprint): the hands and the current forces on the left, the
//! per-finger time series, force histories, link health and latency on the right.

use rerun::blueprint::{
    components::PanelState, BarChartView, Blueprint, BlueprintPanel, ContainerLike, Grid,
    Horizontal, SelectionPanel, Spatial3DView, TimePanel, TimeSeriesView, Vertical,
};

use crate::content::{force_path, POSITION_SERIES, RECORDING_TIME};
use crate::kinematics::FINGERS;

/// A time series view over one force of every finger.
fn finger_forces(name: &str, which: &str) -> TimeSeriesView {
    TimeSeriesView::new(name)
        .with_origin("/")
        .with_contents(FINGERS.map(|f| format!("+ /{}", force_path(f, which))))
}

/// The layout a person reads at a glance:
///
/// ```text
/// +-----------------------------+--------------------------------------------+
/// |                             | thumb   | index   | middle   closure 0..1: |
/// | Hands (3D): the operator    | ring    | little  | thumb     glove, cmd,  |
/// | (left) and the Revo2        |         |         | rotation  measured     |
/// | (right), contacts, arrows   +----------------------+---------------------+
/// |                             | tactile normal (N)   | glove force command |
/// +--------------+--------------+----------------------+---------------------+
/// | tactile now  | glove now    | link health          | latency (ms)        |
/// +--------------+--------------+----------------------+---------------------+
/// ```
///
/// The time panel shows [`RECORDING_TIME`]; the blueprint and selection panels start
/// collapsed, and no views are added automatically.
pub fn default_blueprint() -> Blueprint {
    let hands = Spatial3DView::new("Hands: operator (left), Revo2 (right)").with_origin("/hands");
    let bars = Horizontal::new([
        BarChartView::new("Tactile normal force now (N), thumb..little")
            .with_origin("/bars/tactile_normal")
            .into(),
        BarChartView::new("Glove force command now, thumb..little")
            .with_origin("/bars/glove_force")
            .into(),
    ]);
    let left = Vertical::new([hands.into(), bars.into()]).with_row_shares([3.0, 1.2]);

    let fingers: Vec<ContainerLike> = POSITION_SERIES
        .iter()
        .map(|f| {
            TimeSeriesView::new(format!("{} closure", f.replace('_', " ")))
                .with_origin(format!("/fingers/{f}/position"))
                .into()
        })
        .collect();
    let fingers = Grid::new(fingers).with_grid_columns(3);
    let forces = Horizontal::new([
        finger_forces("Tactile normal force (N)", "tactile_normal").into(),
        finger_forces("Glove force command (glove units)", "glove_command").into(),
    ]);
    let status = Horizontal::new([
        TimeSeriesView::new("Link health (counts since start)")
            .with_origin("/health")
            .into(),
        TimeSeriesView::new("Latency per stage (ms)")
            .with_origin("/latency")
            .into(),
    ]);
    let right = Vertical::new([fingers.into(), forces.into(), status.into()])
        .with_row_shares([2.0, 1.0, 1.0]);

    Blueprint::new(Horizontal::new([left.into(), right.into()]).with_column_shares([2.2, 3.0]))
        .with_auto_views(false)
        .with_blueprint_panel(BlueprintPanel::from_state(PanelState::Collapsed))
        .with_selection_panel(SelectionPanel::from_state(PanelState::Collapsed))
        .with_time_panel(TimePanel::new().with_timeline(RECORDING_TIME))
}
