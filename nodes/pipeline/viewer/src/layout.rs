//! The default layout (a rerun blueprint): the hands and the current forces on the left, the
//! per-finger closure plots, force histories, link health and latency on the right. What
//! depends on the robot hand comes from the content layer's [`Layout`].

use rerun::blueprint::{
    components::PanelState, BarChartView, Blueprint, BlueprintPanel, ContainerLike, Grid,
    Horizontal, SelectionPanel, Spatial3DView, TimePanel, TimeSeriesView, Vertical,
};

use crate::content::{Layout, Plot, RECORDING_TIME};

/// A time series view over the plot's entity paths.
fn series_view(plot: &Plot) -> TimeSeriesView {
    TimeSeriesView::new(plot.title.as_str())
        .with_origin("/")
        .with_contents(plot.contents.iter().map(|p| format!("+ /{p}")))
}

/// The layout a person reads at a glance:
///
/// ```text
/// +-----------------------------+--------------------------------------------+
/// |                             | a closure plot per robot finger (its       |
/// | Hands (3D): the operator    | joints commanded and measured, 0 = open .. |
/// | (left) and the robot hand   | 1 = closed, and the glove channels that    |
/// | (right), contacts, arrows   | drive them), three per row                 |
/// |                             +----------------------+---------------------+
/// |                             | tactile (per tip)    | glove force command |
/// +--------------+--------------+----------------------+---------------------+
/// | tactile now  | glove now    | link health          | latency (ms)        |
/// +--------------+--------------+----------------------+---------------------+
/// ```
///
/// Without fingertip sensors the tactile views are left out. The time panel shows
/// [`RECORDING_TIME`]; the blueprint and selection panels start collapsed, and no views are
/// added automatically.
pub fn default_blueprint(layout: &Layout) -> Blueprint {
    let hands = Spatial3DView::new(layout.hands_title.as_str()).with_origin("/hands");
    let glove_bars: ContainerLike = BarChartView::new("Glove force command now, thumb..little")
        .with_origin("/bars/glove_force")
        .into();
    let bars = match &layout.tactile {
        Some((title, _)) => Horizontal::new([
            BarChartView::new(title.as_str())
                .with_origin("/bars/tactile")
                .into(),
            glove_bars,
        ]),
        None => Horizontal::new([glove_bars]),
    };
    let left = Vertical::new([hands.into(), bars.into()]).with_row_shares([3.0, 1.2]);

    let fingers: Vec<ContainerLike> = layout
        .closures
        .iter()
        .map(|plot| series_view(plot).into())
        .collect();
    let fingers = Grid::new(fingers).with_grid_columns(3);
    let glove_force = TimeSeriesView::new("Glove force command (glove units)")
        .with_origin("/glove/force")
        .into();
    let forces = match &layout.tactile {
        Some((_, plot)) => Horizontal::new([series_view(plot).into(), glove_force]),
        None => Horizontal::new([glove_force]),
    };
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
