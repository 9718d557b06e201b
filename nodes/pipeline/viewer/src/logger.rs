//! The rerun layer: logs the content layer's [`Frame`]s and [`Entry`]s to a
//! [`rerun::RecordingStream`] (whatever its sink: a viewer, a file, memory), converting the
//! plain values to rerun archetypes at this boundary only, and sends the layout
//! ([`default_blueprint`]) when the content asks for one.

use rerun::blueprint::BlueprintActivation;
use rerun::{
    Arrows3D, BarChart, Color, LineStrips3D, Points3D, Radius, RecordingStream,
    RecordingStreamResult, Scalars, SeriesLines, TextDocument, TimeCell, Transform3D,
    ViewCoordinates,
};

use crate::content::{Entry, Frame, Layout, Rgba, Scene, Visual, RECORDING_TIME, SAMPLE_TIME};
use crate::layout::default_blueprint;

fn color(c: Rgba) -> Color {
    Color::from_unmultiplied_rgba(c[0], c[1], c[2], c[3])
}

/// Logs content to one recording stream.
#[derive(Clone)]
pub struct RerunLogger {
    rec: RecordingStream,
}

impl RerunLogger {
    /// Logs to `rec`.
    pub fn new(rec: RecordingStream) -> Self {
        Self { rec }
    }

    /// The stream.
    pub fn stream(&self) -> &RecordingStream {
        &self.rec
    }

    /// Logs timeless entries (series styles, placements, the coordinate convention).
    pub fn log_static(&self, entries: &[Entry]) -> RecordingStreamResult<()> {
        for entry in entries {
            self.log_entry(entry, true)?;
        }
        Ok(())
    }

    /// Sends `layout` as the default blueprint and makes it the active one.
    pub fn send_layout(&self, layout: &Layout) -> RecordingStreamResult<()> {
        default_blueprint(layout).send(&self.rec, BlueprintActivation::default())
    }

    /// What a scene shows before its first sample: its timeless entries and its layout.
    pub fn log_scene(&self, scene: &Scene) -> RecordingStreamResult<()> {
        self.log_static(&scene.static_entries())?;
        self.send_layout(&scene.layout())
    }

    /// Logs a frame at its point of both timelines (and its timeless entries and layout, if
    /// any).
    pub fn log_frame(&self, frame: &Frame) -> RecordingStreamResult<()> {
        self.log_static(&frame.statics)?;
        if let Some(layout) = &frame.layout {
            self.send_layout(layout)?;
        }
        self.rec.set_time(
            RECORDING_TIME,
            TimeCell::from_duration_nanos(frame.recording_time_ns),
        );
        self.rec.set_time(
            SAMPLE_TIME,
            TimeCell::from_duration_nanos(frame.sample_time_ns),
        );
        for entry in &frame.entries {
            self.log_entry(entry, false)?;
        }
        Ok(())
    }

    fn log_entry(&self, entry: &Entry, timeless: bool) -> RecordingStreamResult<()> {
        let path = entry.path.as_str();
        let rec = &self.rec;
        let log = |archetype: &dyn rerun::AsComponents| {
            if timeless {
                rec.log_static(path, archetype)
            } else {
                rec.log(path, archetype)
            }
        };
        match &entry.visual {
            Visual::Scalar(v) => log(&Scalars::single(*v)),
            Visual::Points {
                positions,
                radii,
                colors,
                labels,
            } => {
                let mut points = Points3D::new(positions.iter().copied())
                    .with_radii(radii.iter().map(|r| Radius::new_scene_units(*r)))
                    .with_colors(colors.iter().map(|c| color(*c)));
                if !labels.is_empty() {
                    points = points
                        .with_labels(labels.iter().map(String::as_str))
                        .with_show_labels(true);
                }
                log(&points)
            }
            Visual::Strips {
                strips,
                radius,
                color: c,
            } => log(&LineStrips3D::new(strips.iter().map(|s| s.iter().copied()))
                .with_radii([Radius::new_scene_units(*radius)])
                .with_colors([color(*c)])),
            Visual::Arrows {
                origins,
                vectors,
                color: c,
            } => log(&Arrows3D::from_vectors(vectors.iter().copied())
                .with_origins(origins.iter().copied())
                .with_colors([color(*c)])),
            Visual::Bars { values, color: c } => {
                log(&BarChart::new(values.as_slice()).with_color(color(*c)))
            }
            Visual::Markdown(text) => {
                log(&TextDocument::new(text.as_str()).with_media_type(rerun::MediaType::markdown()))
            }
            Visual::Series { name, color: c } => log(&SeriesLines::new()
                .with_names([name.as_str()])
                .with_colors([color(*c)])),
            Visual::Translation(t) => log(&Transform3D::from_translation(*t)),
            Visual::ZUp => log(&ViewCoordinates::RIGHT_HAND_Z_UP()),
        }
    }
}
