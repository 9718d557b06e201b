//! `teleop echo`'s readable samples: one sample of any topic, and the hand profile that names
//! its joints and fingertips, in, text out. No I/O here; the subscription loop lives in
//! `inspect`, which writes the text and the warnings ([`Echo::take_warnings`]).
//!
//! A sample becomes a tree of named values ([`Value`]), then text in one of three [`Format`]s:
//!
//! * YAML (the default): one document per sample, starting `---`; a table of plain values on
//!   one line (`index: {position: 0.5, speed: 0.0, ...}`), NaN as `.nan`, infinities as
//!   `.inf`/`-.inf`, texts plain when they are simple names, else double-quoted. YAML 1.1
//!   readers (PyYAML) read it as YAML 1.2 ones do: every float has a dot and every exponent a
//!   sign, and names such as `on` or `no` are quoted.
//! * JSON: one object per line (JSON Lines), NaN and infinities as `null`.
//! * CSV: one header line, then one row per sample; a column is the dotted path of a value
//!   (`joints.index.position`, `header.seq`, `input_age_ms.0`). NaN and a value the sample does
//!   not have are empty cells. The columns are fixed for a run, so that CSV readers
//!   (`csv.DictReader`, pandas) see one header: a hand topic's are the joints or fingertips of
//!   the profile naming the run's first hand sample, every one of them whether a sample uses it
//!   or not, and every fingertip field whatever the sensor fills; `health`'s are every input
//!   age slot and the details as `detail.<i>.name` / `detail.<i>.value` for each of the
//!   contract's slots (a report of any node fits them). A sample with values the header has no
//!   column for (more joints than the first) has them left out, said once as a warning.
//!
//! What a sample shows:
//!
//! * `hand/command`, `hand/state`, `hand/tactile`: only the used joints and fingertips, named by
//!   the hand profile of the sample's `hand_model` (the shipped one, or the one given), joints
//!   in the profile's joint order, fingertips in its finger order (the fingers with a tip
//!   sensor, `hand/tactile`'s order); an entry the profile does not name is `joint_<i>` /
//!   `fingertip_<i>`. Units are in the names where the contract fixes them (`effort_nm`,
//!   `current_ma`, `normal_n`); positions and speeds are in the sample's `units`. A profile
//!   given (`--profile`) names every hand sample, also one of another hand model (a lab's own
//!   hand may reuse a shipped hand's model id), with a warning, once, that the models differ;
//!   in CSV the profile of the run's first hand sample names the later ones, with the same
//!   warning.
//! * Glove topics: by the glove's channel and finger names ([`GLOVE_CHANNELS`],
//!   [`GLOVE_FINGERS`]).
//! * `health`: node name, loop rate, input ages, counters and the named details.
//! * `device/info`: the identity by field name ([`DeviceInfo::named_fields`]).
//! * `episode`: the event and outcome by name, the task as text; `estop` and `estop/ack`:
//!   `engaged` as true (1) or false (0).
//! * Every other topic by its field table ([`Message::FIELDS`], the payload's ROS 2 schema),
//!   without the `reserved` fields; fixed byte fields of 16 bytes or more are the contract's
//!   zero-padded UTF-8 texts.
//!
//! Enumerations show their names (`control_mode: position`, `source: tactile`), bit sets their
//! bits by name (`flags: {held: false, clamped: true, ...}`); a value the contract does not
//! name shows as its number.

use std::collections::{BTreeMap, HashMap};

use teleop_hand_profile::HandProfile;
use teleop_msgs::{
    command_flags, contact_source, control_mode, device_model, episode_event, episode_outcome,
    fingertip_sensor, force_flags, link_kind, text_of, units, DeviceInfo, EStop, EStopAck, Episode,
    Fingertip, GloveDiagnostics, GloveForceCommand, GloveState, HandCommand, HandState,
    JointCommand, JointState, Message, NodeHealth, SampleHeader, Tactile, GLOVE_CHANNELS,
    GLOVE_FINGERS, MAX_HEALTH_DETAILS,
};

/// How `teleop echo` writes samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Format {
    /// One YAML document per sample.
    #[default]
    Yaml,
    /// One JSON object per line.
    Json,
    /// A header line, then one row per sample.
    Csv,
}

/// One value of a sample.
#[derive(Debug, Clone, PartialEq)]
enum Value {
    /// A value the sample does not have (a CSV column of a joint it does not use): `null`, an
    /// empty cell.
    Null,
    Bool(bool),
    Int(i128),
    F32(f32),
    F64(f64),
    Text(String),
    List(Vec<Value>),
    Map(Fields),
}

/// Named values in their order.
type Fields = Vec<(String, Value)>;

macro_rules! value_from {
    ($variant:ident: $($t:ty),*) => {
        $(impl From<$t> for Value {
            fn from(v: $t) -> Self {
                Value::$variant(v.into())
            }
        })*
    };
}
value_from!(Int: u8, u16, u32, u64, i8, i16, i32, i64);
value_from!(Bool: bool);
value_from!(F32: f32);
value_from!(F64: f64);
value_from!(Text: String, &str);

impl<T: Into<Value>> From<Option<T>> for Value {
    fn from(v: Option<T>) -> Self {
        v.map_or(Value::Null, Into::into)
    }
}

/// `(name, value)` for a [`Fields`] list.
fn entry(name: &str, value: impl Into<Value>) -> (String, Value) {
    (name.to_string(), value.into())
}

/// Writes samples in one format, naming hand samples by their hand profiles.
pub struct Echo {
    format: Format,
    /// The profile given (`--profile`): it names every hand sample's joints and fingertips.
    profile: Option<HandProfile>,
    /// The shipped profile of each hand model met so far (`None`: there is none).
    shipped: BTreeMap<u8, Option<HandProfile>>,
    /// CSV without a profile given: the first hand sample's model, whose shipped profile names
    /// every hand sample of the run (the columns are fixed).
    first_model: Option<u8>,
    /// CSV: the columns of the header, written before the first row.
    columns: Option<Vec<String>>,
    /// Warnings not yet taken ([`Echo::take_warnings`]).
    warnings: Vec<String>,
    /// Whether a hand sample named by another model's profile was warned of.
    warned_model: bool,
    /// Whether a CSV sample with values the header has no column for was warned of.
    warned_columns: bool,
}

impl Echo {
    /// An echo in `format`; `profile`, if given, names the joints and fingertips of every hand
    /// sample instead of the shipped profile of the sample's hand model.
    pub fn new(format: Format, profile: Option<HandProfile>) -> Self {
        Self {
            format,
            profile,
            shipped: BTreeMap::new(),
            first_model: None,
            columns: None,
            warnings: Vec::new(),
            warned_model: false,
            warned_columns: false,
        }
    }

    /// The text of one sample (without a final line break): a YAML document, a JSON line, or
    /// a CSV row (the first after the header line).
    pub fn show<M: Message>(&mut self, sample: &M) -> String {
        let fields = self.fields(sample);
        match self.format {
            Format::Yaml => format!("---\n{}", yaml_block(&fields, 0)),
            Format::Json => json_map(&fields),
            Format::Csv => {
                let mut cells = Vec::new();
                flatten("", &Value::Map(fields), &mut cells);
                let Some(columns) = &self.columns else {
                    let header: Vec<String> = cells.iter().map(|(k, _)| csv_cell(k)).collect();
                    let row: Vec<String> = cells.iter().map(|(_, v)| v.clone()).collect();
                    self.columns = Some(cells.into_iter().map(|(k, _)| k).collect());
                    return format!("{}\n{}", header.join(","), row.join(","));
                };
                // The header's columns, whatever this sample has.
                let at: HashMap<&str, usize> = columns
                    .iter()
                    .enumerate()
                    .map(|(i, c)| (c.as_str(), i))
                    .collect();
                let mut row = vec![String::new(); columns.len()];
                let mut left_out = Vec::new();
                for (column, cell) in cells {
                    match at.get(column.as_str()) {
                        Some(&i) => row[i] = cell,
                        None => left_out.push(column),
                    }
                }
                if !left_out.is_empty() && !self.warned_columns {
                    self.warned_columns = true;
                    self.warnings.push(format!(
                        "{}: values without a column in the CSV header (fixed by the first \
                         sample) are left out: {}",
                        M::TOPIC,
                        left_out.join(", ")
                    ));
                }
                row.join(",")
            }
        }
    }

    /// The warnings since the last call, each for standard error (said once per run: a hand
    /// sample named by another model's profile, CSV values left out).
    pub fn take_warnings(&mut self) -> Vec<String> {
        std::mem::take(&mut self.warnings)
    }

    /// Whether the columns are fixed (CSV): every slot a sample may use is shown, those it
    /// does not as [`Value::Null`].
    fn fixed(&self) -> bool {
        self.format == Format::Csv
    }

    /// The sample as named values.
    fn fields<M: Message>(&mut self, sample: &M) -> Fields {
        if let Some(c) = payload::<HandCommand, M>(sample) {
            return self.hand_command(&c);
        }
        if let Some(s) = payload::<HandState, M>(sample) {
            return self.hand_state(&s);
        }
        if let Some(t) = payload::<Tactile, M>(sample) {
            return self.tactile(&t);
        }
        if let Some(g) = payload::<GloveState, M>(sample) {
            return glove_state(&g);
        }
        if let Some(d) = payload::<GloveDiagnostics, M>(sample) {
            return glove_diagnostics(&d);
        }
        if let Some(f) = payload::<GloveForceCommand, M>(sample) {
            return glove_force_command(&f);
        }
        if let Some(h) = payload::<NodeHealth, M>(sample) {
            return health(&h, self.fixed());
        }
        if let Some(e) = payload::<Episode, M>(sample) {
            return episode(&e);
        }
        if let Some(e) = payload::<EStop, M>(sample) {
            return vec![
                entry("header", header(&e.header)),
                entry("engaged", engaged(e.engaged)),
            ];
        }
        if let Some(a) = payload::<EStopAck, M>(sample) {
            return vec![
                entry("header", header(&a.header)),
                entry("engaged", engaged(a.engaged)),
                entry("node_name", text_of(&a.node_name)),
            ];
        }
        if let Some(d) = payload::<DeviceInfo, M>(sample) {
            let mut fields = vec![entry("header", header(&d.header))];
            fields.extend(d.named_fields().into_iter().map(|(k, v)| entry(k, v)));
            return fields;
        }
        by_fields(
            M::FIELDS
                .iter()
                .map(|f| (f.name, f.ros_type, f.offset, f.size)),
            sample.as_bytes(),
            &M::nested(),
        )
    }

    /// The profile naming the joints and fingertips of a sample of hand model `model`, if
    /// there is one: the one given, else (CSV) the shipped one of the run's first hand
    /// sample's model, else the shipped one of `model`. Warns once when that profile is
    /// another model's.
    fn profile(&mut self, model: u8) -> Option<&HandProfile> {
        if let Some(given) = &self.profile {
            if given.model_id != model && !self.warned_model {
                self.warned_model = true;
                self.warnings.push(format!(
                    "a sample of hand model {} ({model}) is named by the profile given, \
                     {:?}, which is of model {} ({}); check that its joints are this hand's",
                    device_model::name(model),
                    given.name,
                    device_model::name(given.model_id),
                    given.model_id
                ));
            }
            return self.profile.as_ref();
        }
        let naming = if self.fixed() {
            *self.first_model.get_or_insert(model)
        } else {
            model
        };
        if naming != model && !self.warned_model {
            self.warned_model = true;
            self.warnings.push(format!(
                "a sample of hand model {} ({model}) is named by the profile of model {} \
                 ({naming}), the first sample's: the CSV columns are fixed for a run",
                device_model::name(model),
                device_model::name(naming),
            ));
        }
        self.shipped
            .entry(naming)
            .or_insert_with(|| HandProfile::builtin_for_model(naming))
            .as_ref()
    }

    /// Names of the joints of a sample of hand model `model` that uses `used` of them: the
    /// first `used`, or with fixed columns every one the profile names and any used past
    /// them.
    fn joint_names(&mut self, model: u8, used: usize) -> Vec<String> {
        let named: Vec<String> = self
            .profile(model)
            .map(|p| p.joint_names().map(str::to_string).collect())
            .unwrap_or_default();
        let count = self.shown(named.len(), used);
        numbered(named, count, "joint")
    }

    /// Names of the fingertips of a sample of hand model `model` that uses `used` of them, as
    /// [`Echo::joint_names`].
    fn fingertip_names(&mut self, model: u8, used: usize) -> Vec<String> {
        let named: Vec<String> = self
            .profile(model)
            .map(|p| p.fingertips().map(|f| f.name.clone()).collect())
            .unwrap_or_default();
        let count = self.shown(named.len(), used);
        numbered(named, count, "fingertip")
    }

    /// How many entries a sample using `used` of them shows when the profile names `named`.
    fn shown(&self, named: usize, used: usize) -> usize {
        if self.fixed() {
            used.max(named)
        } else {
            used
        }
    }

    fn hand_command(&mut self, c: &HandCommand) -> Fields {
        let used = c.active_joints();
        let names = self.joint_names(c.hand_model, used.len());
        let joints = names
            .into_iter()
            .enumerate()
            .map(|(i, name)| {
                let j: Option<&JointCommand> = used.get(i);
                let fields = vec![
                    entry("target", j.map(|j| j.target)),
                    entry("speed_limit", j.map(|j| j.speed_limit)),
                    entry("effort_limit", j.map(|j| j.effort_limit)),
                ];
                (name, Value::Map(fields))
            })
            .collect();
        vec![
            entry("header", header(&c.header)),
            entry("hand", device_model::name(c.hand_model)),
            entry(
                "control_mode",
                named(
                    c.control_mode,
                    &[
                        (control_mode::POSITION, "position"),
                        (control_mode::POSITION_TIME, "position_time"),
                        (control_mode::VELOCITY, "velocity"),
                        (control_mode::EFFORT, "effort"),
                        (control_mode::DUTY, "duty"),
                    ],
                ),
            ),
            entry("units", units_name(c.units)),
            entry(
                "flags",
                bits(
                    c.flags,
                    &[
                        (command_flags::HELD, "held"),
                        (command_flags::CLAMPED, "clamped"),
                        (command_flags::SLEW_LIMITED, "slew_limited"),
                    ],
                ),
            ),
            ("joints".to_string(), Value::Map(joints)),
        ]
    }

    fn hand_state(&mut self, s: &HandState) -> Fields {
        let used = s.active_joints();
        let names = self.joint_names(s.hand_model, used.len());
        let joints = names
            .into_iter()
            .enumerate()
            .map(|(i, name)| {
                let j: Option<&JointState> = used.get(i);
                let fields = vec![
                    entry("position", j.map(|j| j.position)),
                    entry("speed", j.map(|j| j.speed)),
                    // The contract: N m whatever `units` says.
                    entry("effort_nm", j.map(|j| j.effort)),
                    entry("current_ma", j.map(|j| j.current_ma)),
                    entry("status", j.map(|j| j.status)),
                ];
                (name, Value::Map(fields))
            })
            .collect();
        let link = vec![
            entry("up", s.link_up != 0),
            entry(
                "kind",
                link_kind::name(s.link_kind).map_or(Value::from(s.link_kind), Value::from),
            ),
            entry("bus_state", s.bus_state),
            entry("error_code", s.link_error_code),
            entry("errors", s.link_errors),
            entry("lost_frames", s.lost_frames),
        ];
        vec![
            entry("header", header(&s.header)),
            entry("hand", device_model::name(s.hand_model)),
            entry("units", units_name(s.units)),
            entry("holding", s.holding != 0),
            ("link".to_string(), Value::Map(link)),
            ("joints".to_string(), Value::Map(joints)),
        ]
    }

    fn tactile(&mut self, t: &Tactile) -> Fields {
        let used = t.active_fingertips();
        let names = self.fingertip_names(t.hand_model, used.len());
        let fixed = self.fixed();
        let tips = names
            .into_iter()
            .enumerate()
            .map(|(i, name)| (name, Value::Map(fingertip(used.get(i), fixed))))
            .collect();
        vec![
            entry("header", header(&t.header)),
            entry("hand", device_model::name(t.hand_model)),
            ("fingertips".to_string(), Value::Map(tips)),
        ]
    }
}

/// The sample as payload type `T`, when `M` is `T`'s topic.
fn payload<T: Message, M: Message>(sample: &M) -> Option<T> {
    if M::TOPIC != T::TOPIC {
        return None;
    }
    T::from_bytes(sample.as_bytes()).ok()
}

/// `count` names: those of `named`, then `<prefix>_<i>` for the entries past them.
fn numbered(mut named: Vec<String>, count: usize, prefix: &str) -> Vec<String> {
    named.truncate(count);
    let first = named.len();
    named.extend((first..count).map(|i| format!("{prefix}_{i}")));
    named
}

/// An enumeration's value: its name from `names`, else its number.
fn named(value: u8, names: &[(u8, &str)]) -> Value {
    names
        .iter()
        .find(|(v, _)| *v == value)
        .map_or(Value::from(value), |(_, name)| Value::from(*name))
}

/// A bit set's bits by name (and `other_bits`, the rest, when any is set).
fn bits(value: u8, names: &[(u8, &str)]) -> Value {
    let mut fields: Fields = names
        .iter()
        .map(|(bit, name)| entry(name, value & bit != 0))
        .collect();
    let known = names.iter().fold(0, |all, (bit, _)| all | bit);
    if value & !known != 0 {
        fields.push(entry("other_bits", value & !known));
    }
    Value::Map(fields)
}

/// The name of a `units` value.
fn units_name(value: u8) -> Value {
    named(
        value,
        &[
            (units::NORMALISED, "normalised"),
            (units::PHYSICAL, "physical"),
        ],
    )
}

fn header(h: &SampleHeader) -> Value {
    Value::Map(vec![
        entry("seq", h.seq),
        entry("stamp_ns", h.stamp_ns),
        entry("origin_ns", h.origin_ns),
        entry("source_id", h.source_id),
    ])
}

/// A fingertip's fields, those its sensor kind fills (all of them for another kind); with
/// `fixed` columns every field, [`Value::Null`] where the sensor kind does not fill it and
/// throughout for a fingertip the sample does not use (`f` is `None`).
fn fingertip(f: Option<&Fingertip>, fixed: bool) -> Fields {
    let kind = f.map(|f| f.sensor_kind);
    let sensor = entry(
        "sensor",
        kind.map(|k| {
            named(
                k,
                &[
                    (fingertip_sensor::NONE, "none"),
                    (fingertip_sensor::REVO2_FORCE, "revo2_force"),
                    (fingertip_sensor::PST_PRESSURE, "pst_pressure"),
                ],
            )
        }),
    );
    let forces = vec![
        entry("normal_n", f.map(|f| f.normal_n)),
        entry("tangential_n", f.map(|f| f.tangential_n)),
        entry("direction_deg", f.map(|f| f.direction_deg)),
        entry("direction_valid", f.map(|f| f.direction_valid != 0)),
        entry("proximity", f.map(|f| f.proximity)),
        entry("status", f.map(|f| f.status)),
        entry("update_counter", f.map(|f| f.update_counter)),
    ];
    let raw = vec![
        entry("pressure", f.map(|f| f.pressure)),
        entry("temperature", f.map(|f| f.temperature)),
    ];
    let (forces_filled, raw_filled) = match kind {
        None | Some(fingertip_sensor::NONE) => (false, false),
        Some(fingertip_sensor::REVO2_FORCE) => (true, false),
        Some(fingertip_sensor::PST_PRESSURE) => (false, true),
        Some(_) => (true, true),
    };
    let mut fields = vec![sensor];
    for (filled, group) in [(forces_filled, forces), (raw_filled, raw)] {
        if filled {
            fields.extend(group);
        } else if fixed {
            fields.extend(group.into_iter().map(|(k, _)| (k, Value::Null)));
        }
    }
    fields
}

fn glove_state(g: &GloveState) -> Fields {
    let channels = GLOVE_CHANNELS
        .iter()
        .enumerate()
        .map(|(i, name)| {
            let mut fields = vec![
                entry("position", g.position[i]),
                entry("raw_position", g.raw_position[i]),
            ];
            if let Some(force) = g.force.get(i) {
                fields.push(entry("force", *force));
            }
            (name.to_string(), Value::Map(fields))
        })
        .collect();
    vec![
        entry("header", header(&g.header)),
        entry("glove_id", g.glove_id),
        entry("link_up", g.link_up != 0),
        entry("exchanges", g.exchanges),
        entry("errors", g.errors),
        ("channels".to_string(), Value::Map(channels)),
    ]
}

fn glove_diagnostics(d: &GloveDiagnostics) -> Fields {
    let fingers = GLOVE_FINGERS
        .iter()
        .enumerate()
        .map(|(i, name)| {
            let fields = vec![
                entry("force", d.force[i]),
                entry("current_ma", d.current_ma[i]),
                entry("error_bits", d.error_bits[i]),
                entry("temperature_c", d.temperature_c[i]),
            ];
            (name.to_string(), Value::Map(fields))
        })
        .collect();
    vec![
        entry("header", header(&d.header)),
        entry("voltage_raw", d.voltage_raw),
        ("fingers".to_string(), Value::Map(fingers)),
    ]
}

fn glove_force_command(f: &GloveForceCommand) -> Fields {
    let sources = [
        (contact_source::NONE, "none"),
        (contact_source::TACTILE, "tactile"),
        (contact_source::POSITION_ERROR, "position_error"),
        (contact_source::CURRENT, "current"),
        (contact_source::RAMPING, "ramping"),
        (contact_source::ESTOP, "estop"),
        (contact_source::EFFORT, "effort"),
    ];
    let fingers = GLOVE_FINGERS
        .iter()
        .enumerate()
        .map(|(i, name)| {
            let fields = vec![
                entry("force", f.force[i]),
                entry("source", named(f.source[i], &sources)),
            ];
            (name.to_string(), Value::Map(fields))
        })
        .collect();
    vec![
        entry("header", header(&f.header)),
        entry(
            "flags",
            bits(
                f.flags,
                &[
                    (force_flags::STALE, "stale"),
                    (force_flags::ESTOP, "estop"),
                    (force_flags::CLAMPED, "clamped"),
                ],
            ),
        ),
        ("fingers".to_string(), Value::Map(fingers)),
    ]
}

/// A health report: the used input ages and the details by name; with `fixed` columns every
/// input age slot (those unused [`Value::Null`]) and the details as a list of every slot's
/// name and value (`detail.<i>.name`, `detail.<i>.value`), so that any node's report has the
/// same columns.
fn health(h: &NodeHealth, fixed: bool) -> Fields {
    let inputs = usize::from(h.input_count).min(h.input_age_ms.len());
    let shown = if fixed { h.input_age_ms.len() } else { inputs };
    let ages = (0..shown).map(|i| Value::from(h.input_age_ms[..inputs].get(i).copied()));
    let details = if fixed {
        let mut used = h.details();
        let slots = (0..MAX_HEALTH_DETAILS).map(|_| {
            let (name, value) = used.next().unzip();
            Value::Map(vec![entry("name", name), entry("value", value)])
        });
        ("detail".to_string(), Value::List(slots.collect()))
    } else {
        let named = h.details().map(|(k, v)| (k, Value::from(v))).collect();
        ("details".to_string(), Value::Map(named))
    };
    vec![
        entry("header", header(&h.header)),
        entry("node", h.name()),
        entry("loop_rate_hz", h.loop_rate_hz),
        ("input_age_ms".to_string(), Value::List(ages.collect())),
        entry("timeouts", h.timeouts),
        entry("clamps", h.clamps),
        entry("errors", h.errors),
        entry("dropped", h.dropped),
        details,
    ]
}

/// An episode mark: its event and outcome by name, its task as text.
fn episode(e: &Episode) -> Fields {
    let event = named(
        e.event,
        &[
            (episode_event::START, "start"),
            (episode_event::STOP, "stop"),
            (episode_event::DISCARD, "discard"),
        ],
    );
    vec![
        entry("header", header(&e.header)),
        entry("event", event),
        // As the recorder reads it: any value but success or failure is unlabelled.
        entry("outcome", episode_outcome::name(e.outcome)),
        entry("task", e.task()),
    ]
}

/// An e-stop state (`engaged`: 1 engaged, 0 released) as true or false; another value as its
/// number.
fn engaged(value: u8) -> Value {
    match value {
        0 => Value::Bool(false),
        1 => Value::Bool(true),
        other => Value::from(other),
    }
}

/// Fixed `uint8` arrays at least this long are texts: the contract's zero-padded UTF-8 fields
/// (names, identities, a task) are 24 bytes or more, its arrays of byte-sized numbers
/// (`error_bits`, `temperature_c`, `source`) 5.
const TEXT_BYTES: usize = 16;

/// A payload or nested struct by its fields `(name, ROS 2 type, offset, size)` over its
/// little-endian bytes (the contract's layout, see `teleop_msgs`), without `reserved` fields;
/// `nested` holds the nested types' `.msg` definitions ([`Message::nested`]).
fn by_fields<'a>(
    fields: impl Iterator<Item = (&'a str, &'a str, usize, usize)>,
    bytes: &[u8],
    nested: &[(&str, String)],
) -> Fields {
    fields
        .filter(|(name, ..)| *name != "reserved")
        .map(|(name, ros_type, offset, size)| {
            let value = bytes
                .get(offset..offset + size)
                .map_or(Value::Text("?".into()), |b| by_type(ros_type, b, nested));
            (name.to_string(), value)
        })
        .collect()
}

/// The value of ROS 2 type `ros_type` (a primitive, a nested type, or a fixed array of either)
/// in `bytes`.
fn by_type(ros_type: &str, bytes: &[u8], nested: &[(&str, String)]) -> Value {
    let array = ros_type
        .strip_suffix(']')
        .and_then(|t| t.split_once('['))
        .and_then(|(element, n)| Some((element, n.parse::<usize>().ok()?)));
    match array {
        None => element(ros_type, bytes, nested),
        Some(("uint8", n)) if n >= TEXT_BYTES => Value::Text(text_of(bytes)),
        Some((ty, n)) if n > 0 && bytes.len().is_multiple_of(n) => Value::List(
            bytes
                .chunks_exact(bytes.len() / n)
                .map(|b| element(ty, b, nested))
                .collect(),
        ),
        Some(_) => Value::Text("?".into()),
    }
}

/// One element of ROS 2 type `ty` (a primitive or a nested type) in `bytes`.
fn element(ty: &str, bytes: &[u8], nested: &[(&str, String)]) -> Value {
    fn le<const N: usize>(bytes: &[u8]) -> Option<[u8; N]> {
        bytes.try_into().ok()
    }
    let value = match ty {
        "bool" => le::<1>(bytes).map(|b| Value::Bool(b[0] != 0)),
        "uint8" => le(bytes).map(|b| Value::from(u8::from_le_bytes(b))),
        "int8" => le(bytes).map(|b| Value::from(i8::from_le_bytes(b))),
        "uint16" => le(bytes).map(|b| Value::from(u16::from_le_bytes(b))),
        "int16" => le(bytes).map(|b| Value::from(i16::from_le_bytes(b))),
        "uint32" => le(bytes).map(|b| Value::from(u32::from_le_bytes(b))),
        "int32" => le(bytes).map(|b| Value::from(i32::from_le_bytes(b))),
        "uint64" => le(bytes).map(|b| Value::from(u64::from_le_bytes(b))),
        "int64" => le(bytes).map(|b| Value::from(i64::from_le_bytes(b))),
        "float32" => le(bytes).map(|b| Value::from(f32::from_le_bytes(b))),
        "float64" => le(bytes).map(|b| Value::from(f64::from_le_bytes(b))),
        _ => nested
            .iter()
            .find(|(name, _)| *name == ty)
            .map(|(_, definition)| Value::Map(by_definition(definition, bytes, nested))),
    };
    value.unwrap_or(Value::Text("?".into()))
}

/// A nested struct by its `.msg` definition (`type name` lines; the contract's structs have no
/// padding, so each field follows the previous one).
fn by_definition(definition: &str, bytes: &[u8], nested: &[(&str, String)]) -> Fields {
    let mut offset = 0;
    let mut fields = Vec::new();
    for (ty, name) in definition.lines().filter_map(|l| l.split_once(' ')) {
        let size = type_size(ty, nested);
        fields.push((name, ty, offset, size));
        offset += size;
    }
    by_fields(fields.into_iter(), bytes, nested)
}

/// Bytes of ROS 2 type `ty` in the contract (0 for a type it does not know).
fn type_size(ty: &str, nested: &[(&str, String)]) -> usize {
    if let Some((element, n)) = ty.strip_suffix(']').and_then(|t| t.split_once('[')) {
        return type_size(element, nested) * n.parse::<usize>().unwrap_or(0);
    }
    match ty {
        "bool" | "uint8" | "int8" => 1,
        "uint16" | "int16" => 2,
        "uint32" | "int32" | "float32" => 4,
        "uint64" | "int64" | "float64" => 8,
        _ => nested
            .iter()
            .find(|(name, _)| *name == ty)
            .map_or(0, |(_, definition)| {
                definition
                    .lines()
                    .filter_map(|l| l.split_once(' '))
                    .map(|(ty, _)| type_size(ty, nested))
                    .sum()
            }),
    }
}

/// A finite float as text that YAML (1.1 and 1.2), JSON and CSV readers all take as a float:
/// the shortest text that reads back to the same value, with a dot in the mantissa and a sign
/// in the exponent (`1.0e-7`, `1.5e+20`).
fn float_text(shortest: String) -> String {
    let Some((mantissa, exponent)) = shortest.split_once('e') else {
        return shortest;
    };
    let mantissa = if mantissa.contains('.') {
        mantissa.to_string()
    } else {
        format!("{mantissa}.0")
    };
    let exponent = if exponent.starts_with('-') {
        exponent.to_string()
    } else {
        format!("+{exponent}")
    };
    format!("{mantissa}e{exponent}")
}

/// A numeric value as text, or the floats that are no number.
enum Number {
    Finite(String),
    NaN,
    Infinite { negative: bool },
}

/// `value` as a number (`None` for a value that is not numeric).
fn number(value: &Value) -> Option<Number> {
    let float = |v: f64, shortest: String| {
        if v.is_nan() {
            Number::NaN
        } else if v.is_infinite() {
            Number::Infinite { negative: v < 0.0 }
        } else {
            Number::Finite(float_text(shortest))
        }
    };
    match value {
        Value::Int(i) => Some(Number::Finite(i.to_string())),
        Value::F32(v) => Some(float(f64::from(*v), format!("{v:?}"))),
        Value::F64(v) => Some(float(*v, format!("{v:?}"))),
        _ => None,
    }
}

/// `text` as a JSON string (also a valid YAML double-quoted scalar).
fn quoted(text: &str) -> String {
    let mut out = String::with_capacity(text.len() + 2);
    out.push('"');
    for c in text.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            c if u32::from(c) < 0x20 || c == '\u{7f}' => {
                out.push_str(&format!("\\u{:04x}", u32::from(c)))
            }
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

// ---- YAML ----

/// A key or text as YAML writes it: plain when it is a simple name that no YAML reader takes
/// for anything but a string, else quoted.
fn yaml_text(key: &str) -> String {
    const SPECIAL: [&str; 11] = [
        "y", "n", "yes", "no", "on", "off", "true", "false", "null", "nan", "inf",
    ];
    let simple = key
        .chars()
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && key
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    if simple && !SPECIAL.contains(&key.to_ascii_lowercase().as_str()) {
        key.to_string()
    } else {
        quoted(key)
    }
}

/// A value on one line (flow style).
fn yaml_flow(value: &Value) -> String {
    match value {
        Value::Bool(b) => b.to_string(),
        Value::Text(t) => yaml_text(t),
        Value::List(items) => {
            let items: Vec<String> = items.iter().map(yaml_flow).collect();
            format!("[{}]", items.join(", "))
        }
        Value::Map(fields) => {
            let fields: Vec<String> = fields
                .iter()
                .map(|(k, v)| format!("{}: {}", yaml_text(k), yaml_flow(v)))
                .collect();
            format!("{{{}}}", fields.join(", "))
        }
        number_value => match number(number_value) {
            Some(Number::Finite(text)) => text,
            Some(Number::NaN) => ".nan".into(),
            Some(Number::Infinite { negative }) => if negative { "-.inf" } else { ".inf" }.into(),
            None => "null".into(),
        },
    }
}

/// A table with one line per field, `indent` spaces in; a field that is a table of tables is a
/// block of its own, a table of plain values is one line.
fn yaml_block(fields: &Fields, indent: usize) -> String {
    let pad = " ".repeat(indent);
    let mut lines = Vec::with_capacity(fields.len());
    for (key, value) in fields {
        let key = yaml_text(key);
        match value {
            Value::Map(inner)
                if !inner.is_empty() && inner.iter().any(|(_, v)| matches!(v, Value::Map(_))) =>
            {
                lines.push(format!("{pad}{key}:\n{}", yaml_block(inner, indent + 2)));
            }
            _ => lines.push(format!("{pad}{key}: {}", yaml_flow(value))),
        }
    }
    lines.join("\n")
}

// ---- JSON ----

fn json(value: &Value) -> String {
    match value {
        Value::Bool(b) => b.to_string(),
        Value::Text(t) => quoted(t),
        Value::List(items) => {
            let items: Vec<String> = items.iter().map(json).collect();
            format!("[{}]", items.join(","))
        }
        Value::Map(fields) => json_map(fields),
        number_value => match number(number_value) {
            Some(Number::Finite(text)) => text,
            _ => "null".into(),
        },
    }
}

fn json_map(fields: &Fields) -> String {
    let fields: Vec<String> = fields
        .iter()
        .map(|(k, v)| format!("{}:{}", quoted(k), json(v)))
        .collect();
    format!("{{{}}}", fields.join(","))
}

// ---- CSV ----

/// A CSV cell: quoted (RFC 4180) when it holds a comma, a quote or a line break.
fn csv_cell(text: &str) -> String {
    if text.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_string()
    }
}

/// The leaves of `value` as (dotted path, cell), in order; a list's elements are numbered.
fn flatten(path: &str, value: &Value, out: &mut Vec<(String, String)>) {
    let child = |name: &str| {
        if path.is_empty() {
            name.to_string()
        } else {
            format!("{path}.{name}")
        }
    };
    match value {
        Value::Map(fields) => {
            for (k, v) in fields {
                flatten(&child(k), v, out);
            }
        }
        Value::List(items) => {
            for (i, v) in items.iter().enumerate() {
                flatten(&child(&i.to_string()), v, out);
            }
        }
        Value::Bool(b) => out.push((path.to_string(), b.to_string())),
        Value::Text(t) => out.push((path.to_string(), csv_cell(t))),
        number_value => {
            let cell = match number(number_value) {
                Some(Number::Finite(text)) => text,
                Some(Number::Infinite { negative }) => if negative { "-inf" } else { "inf" }.into(),
                Some(Number::NaN) | None => String::new(),
            };
            out.push((path.to_string(), cell));
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use teleop_msgs::{EStop, EStopAck, JointState};

    const HANDS: [&str; 4] = ["revo2", "allegro", "shadow", "leap"];

    fn profile(hand: &str) -> HandProfile {
        HandProfile::builtin(hand).unwrap()
    }

    /// A state of `profile`'s hand with its joints used (position `i / 10`, effort NaN) and
    /// every unused slot filled with 9, so that showing one would be seen.
    fn state(profile: &HandProfile) -> HandState {
        let used = profile.joints.len();
        let mut s = HandState {
            hand_model: profile.model_id,
            joint_count: used as u8,
            units: units::PHYSICAL,
            link_up: 1,
            link_kind: link_kind::ETHERCAT,
            joints: [JointState {
                position: 9.0,
                ..Default::default()
            }; teleop_msgs::MAX_JOINTS],
            ..Default::default()
        };
        s.header.seq = 7;
        for (i, j) in s.joints[..used].iter_mut().enumerate() {
            j.position = i as f32 / 10.0;
            j.effort = f32::NAN;
            j.current_ma = 120.0;
        }
        s
    }

    fn command(profile: &HandProfile) -> HandCommand {
        let mut c = HandCommand {
            hand_model: profile.model_id,
            joint_count: profile.joints.len() as u8,
            control_mode: control_mode::POSITION,
            flags: command_flags::CLAMPED,
            ..Default::default()
        };
        for (i, j) in c.joints.iter_mut().enumerate() {
            j.target = i as f32;
        }
        c
    }

    fn show<M: Message>(format: Format, sample: &M) -> String {
        Echo::new(format, None).show(sample)
    }

    /// The keys of the YAML block under `key:` (one level in), in order.
    fn yaml_keys(yaml: &str, key: &str) -> Vec<String> {
        yaml.lines()
            .skip_while(|l| *l != format!("{key}:"))
            .skip(1)
            .take_while(|l| l.starts_with("  "))
            .filter_map(|l| l.trim_start().split_once(':').map(|(k, _)| k.to_string()))
            .collect()
    }

    /// The names in `json_line`'s object `key`, in the order written.
    fn json_keys(json_line: &str, key: &str) -> Vec<String> {
        let value: serde_json::Value = serde_json::from_str(json_line).unwrap();
        let object = value[key].as_object().unwrap();
        let mut names: Vec<String> = object.keys().cloned().collect();
        names.sort_by_key(|n| json_line.find(&format!("\"{n}\":{{")).unwrap());
        names
    }

    /// The CSV header's columns and each row's cells; every row has as many cells as the header.
    fn csv(text: &str) -> (Vec<String>, Vec<Vec<String>>) {
        let mut lines = text.lines();
        let header: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
        let rows: Vec<Vec<String>> = lines
            .map(|l| l.split(',').map(String::from).collect())
            .collect();
        for row in &rows {
            assert_eq!(row.len(), header.len(), "{text}");
        }
        (header, rows)
    }

    /// The joints named by a CSV header's position columns, in order.
    fn joint_columns(header: &[String]) -> Vec<&str> {
        header
            .iter()
            .filter_map(|c| c.strip_prefix("joints.")?.strip_suffix(".position"))
            .collect()
    }

    #[test]
    fn hand_states_show_each_hands_used_joints_by_name_in_every_format() {
        for hand in HANDS {
            let profile = profile(hand);
            let names: Vec<String> = profile.joint_names().map(String::from).collect();
            let s = state(&profile);

            let yaml = show(Format::Yaml, &s);
            assert!(yaml.starts_with("---\nheader: {seq: 7, "), "{yaml}");
            assert!(yaml.contains(&format!("\nhand: {hand}\n")), "{yaml}");
            assert!(
                yaml.contains("\nlink: {up: true, kind: ethercat, "),
                "{yaml}"
            );
            assert_eq!(yaml_keys(&yaml, "joints"), names, "{hand}: {yaml}");
            assert!(
                yaml.contains(&format!(
                    "  {}: {{position: 0.1, speed: 0.0, effort_nm: .nan, current_ma: 120.0, status: 0}}",
                    names[1]
                )),
                "{yaml}"
            );
            assert!(!yaml.contains("9.0"), "an unused joint shown: {yaml}");

            let json = show(Format::Json, &s);
            assert!(!json.contains('\n'), "one line: {json}");
            assert_eq!(json_keys(&json, "joints"), names, "{hand}: {json}");
            let parsed: serde_json::Value = serde_json::from_str(&json).unwrap();
            let second = &parsed["joints"][&names[1]];
            // The shortest text of the f32: read as an f32, the same value.
            let position = second["position"].as_f64().map(|v| v as f32);
            assert_eq!(position, Some(0.1), "{json}");
            assert!(second["effort_nm"].is_null(), "NaN is null: {json}");
            assert_eq!(parsed["header"]["seq"], 7);

            let text = show(Format::Csv, &s);
            let (header, rows) = csv(&text);
            assert_eq!(rows.len(), 1, "{text}");
            let joint_columns = joint_columns(&header);
            assert_eq!(joint_columns, names, "{hand}: {text}");
            let cell = |column: &str| {
                let at = header.iter().position(|c| c == column).unwrap();
                rows[0][at].clone()
            };
            assert_eq!(cell(&format!("joints.{}.position", names[1])), "0.1");
            assert_eq!(
                cell(&format!("joints.{}.effort_nm", names[1])),
                "",
                "NaN is empty"
            );
            assert_eq!(cell("header.seq"), "7");
            assert_eq!(cell("hand"), hand);
        }
    }

    #[test]
    fn hand_commands_show_each_hands_used_joints_by_name_in_every_format() {
        for hand in HANDS {
            let profile = profile(hand);
            let names: Vec<String> = profile.joint_names().map(String::from).collect();
            let c = command(&profile);
            let yaml = show(Format::Yaml, &c);
            assert_eq!(yaml_keys(&yaml, "joints"), names, "{hand}: {yaml}");
            assert!(yaml.contains("\ncontrol_mode: position\n"), "{yaml}");
            assert!(
                yaml.contains("\nflags: {held: false, clamped: true, slew_limited: false}\n"),
                "{yaml}"
            );
            let last = names.len() - 1;
            assert!(
                yaml.ends_with(&format!(
                    "  {}: {{target: {last}.0, speed_limit: 0.0, effort_limit: 0.0}}",
                    names[last]
                )),
                "{yaml}"
            );
            let json = show(Format::Json, &c);
            assert_eq!(json_keys(&json, "joints"), names, "{hand}: {json}");
            let (header, rows) = csv(&show(Format::Csv, &c));
            let targets: Vec<&str> = header
                .iter()
                .filter_map(|c| c.strip_prefix("joints.")?.strip_suffix(".target"))
                .collect();
            assert_eq!(targets, names, "{hand}");
            assert!(header.contains(&"flags.clamped".to_string()));
            assert_eq!(rows.len(), 1);
            // Joint i's target is i: each value under its own joint's name.
            let parsed: serde_json::Value = serde_json::from_str(&json).unwrap();
            for (i, name) in names.iter().enumerate() {
                assert!(
                    yaml.contains(&format!("\n  {name}: {{target: {i}.0, ")),
                    "{name}: {yaml}"
                );
                assert_eq!(parsed["joints"][name]["target"], i as f64, "{name}: {json}");
                let at = header
                    .iter()
                    .position(|c| *c == format!("joints.{name}.target"))
                    .unwrap();
                assert_eq!(rows[0][at], format!("{i}.0"), "{name}");
            }
        }
    }

    #[test]
    fn tactile_shows_the_fingertips_by_the_profiles_finger_names() {
        for (hand, kind) in [
            ("revo2", fingertip_sensor::REVO2_FORCE),
            ("shadow", fingertip_sensor::PST_PRESSURE),
        ] {
            let profile = profile(hand);
            let names: Vec<String> = profile.fingertips().map(|f| f.name.clone()).collect();
            let mut t = Tactile {
                hand_model: profile.model_id,
                fingertip_count: names.len() as u8,
                ..Default::default()
            };
            for (i, f) in t.fingertips.iter_mut().enumerate() {
                f.sensor_kind = kind;
                f.normal_n = i as f32 + 0.5;
                f.pressure = 100 + i as i32;
            }
            let yaml = show(Format::Yaml, &t);
            assert_eq!(yaml_keys(&yaml, "fingertips"), names, "{hand}: {yaml}");
            let json = show(Format::Json, &t);
            assert_eq!(json_keys(&json, "fingertips"), names, "{hand}: {json}");
            let (header, _) = csv(&show(Format::Csv, &t));
            let sensors: Vec<&str> = header
                .iter()
                .filter_map(|c| c.strip_prefix("fingertips.")?.strip_suffix(".sensor"))
                .collect();
            assert_eq!(sensors, names, "{hand}");
            // Only the fields the sensor fills.
            let first = &names[0];
            match kind {
                fingertip_sensor::REVO2_FORCE => {
                    assert!(yaml.contains(&format!(
                        "  {first}: {{sensor: revo2_force, normal_n: 0.5, "
                    )));
                    assert!(!yaml.contains("pressure"), "{yaml}");
                }
                _ => {
                    assert!(yaml.contains(&format!(
                        "  {first}: {{sensor: pst_pressure, pressure: 100, temperature: 0}}"
                    )));
                    assert!(!yaml.contains("normal_n"), "{yaml}");
                }
            }
        }
    }

    #[test]
    fn a_given_profile_names_the_joints_and_entries_past_it_are_numbered() {
        // A lab's own hand: the Allegro's 16 joints under the LEAP's names.
        let mut s = state(&profile("allegro"));
        let leap = profile("leap");
        let shown = Echo::new(Format::Yaml, Some(leap.clone())).show(&s);
        let names: Vec<String> = leap.joint_names().map(String::from).collect();
        assert_eq!(yaml_keys(&shown, "joints"), names, "{shown}");
        // No profile for the model: numbered.
        s.hand_model = 200;
        s.joint_count = 2;
        let shown = show(Format::Yaml, &s);
        assert_eq!(
            yaml_keys(&shown, "joints"),
            ["joint_0", "joint_1"],
            "{shown}"
        );
        assert!(shown.contains("\nhand: unknown\n"), "{shown}");
    }

    #[test]
    fn glove_topics_show_the_gloves_channel_and_finger_names() {
        let mut g = GloveState {
            link_up: 1,
            ..Default::default()
        };
        g.raw_position[5] = 250;
        g.position[5] = 0.25;
        g.force[4] = -3;
        let yaml = show(Format::Yaml, &g);
        assert_eq!(yaml_keys(&yaml, "channels"), GLOVE_CHANNELS, "{yaml}");
        assert!(
            yaml.contains("  thumb: {position: 0.0, raw_position: 0, force: -3}"),
            "{yaml}"
        );
        assert!(
            yaml.ends_with("  thumb_rotation: {position: 0.25, raw_position: 250}"),
            "{yaml}"
        );
        let f = GloveForceCommand {
            flags: force_flags::ESTOP,
            source: [contact_source::ESTOP; 5],
            ..Default::default()
        };
        let yaml = show(Format::Yaml, &f);
        assert_eq!(yaml_keys(&yaml, "fingers"), GLOVE_FINGERS, "{yaml}");
        assert!(
            yaml.contains("\nflags: {stale: false, estop: true, clamped: false}\n"),
            "{yaml}"
        );
        assert!(
            yaml.contains("  index: {force: 0, source: estop}"),
            "{yaml}"
        );
        let d = GloveDiagnostics::default();
        let (header, _) = csv(&show(Format::Csv, &d));
        assert!(
            header.contains(&"fingers.little.temperature_c".to_string()),
            "{header:?}"
        );
    }

    #[test]
    fn health_shows_node_rates_counters_and_named_details() {
        let mut h = NodeHealth {
            loop_rate_hz: 500.0,
            input_count: 2,
            input_age_ms: [1.5, -1.0, 7.0, 7.0, 7.0],
            errors: 3,
            ..Default::default()
        };
        h.set_name("left/allegro");
        h.set_detail("reconnects", 2.0);
        h.set_detail("rtt_ms", 0.25);
        let yaml = show(Format::Yaml, &h);
        for line in [
            "\nnode: \"left/allegro\"\n",
            "\nloop_rate_hz: 500.0\n",
            "\ninput_age_ms: [1.5, -1.0]\n",
            "\nerrors: 3\n",
        ] {
            assert!(yaml.contains(line), "{line:?} in {yaml}");
        }
        assert!(
            yaml.ends_with("\ndetails: {reconnects: 2.0, rtt_ms: 0.25}"),
            "{yaml}"
        );
        let json: serde_json::Value = serde_json::from_str(&show(Format::Json, &h)).unwrap();
        assert_eq!(json["details"]["rtt_ms"], 0.25);
        assert_eq!(json["input_age_ms"], serde_json::json!([1.5, -1.0]));

        // CSV: reports of nodes with other inputs and details have the same columns, those of
        // every slot, under one header.
        let mut other = NodeHealth {
            input_count: 5,
            input_age_ms: [0.5, 1.5, 2.5, 3.5, 4.5],
            ..Default::default()
        };
        other.set_name("glove");
        for i in 0..MAX_HEALTH_DETAILS {
            other.set_detail(&format!("d{i}"), i as f64);
        }
        let mut echo = Echo::new(Format::Csv, None);
        let text = [&h, &other, &NodeHealth::default(), &h]
            .map(|report| echo.show(report))
            .join("\n");
        assert!(echo.take_warnings().is_empty());
        let (header, rows) = csv(&text);
        assert_eq!(rows.len(), 4, "one header, a row per report: {text}");
        assert!(text.starts_with("header.seq,"), "{text}");
        let mut expected: Vec<String> = (0..5).map(|i| format!("input_age_ms.{i}")).collect();
        for i in 0..MAX_HEALTH_DETAILS {
            expected.push(format!("detail.{i}.name"));
            expected.push(format!("detail.{i}.value"));
        }
        for column in &expected {
            assert!(header.contains(column), "{column}: {header:?}");
        }
        assert!(
            !header.iter().any(|c| c.starts_with("details.")),
            "{header:?}"
        );
        let cell = |row: usize, column: &str| {
            let at = header.iter().position(|c| c == column).unwrap();
            rows[row][at].as_str()
        };
        assert_eq!(cell(0, "node"), "left/allegro");
        assert_eq!(cell(0, "input_age_ms.1"), "-1.0");
        assert_eq!(cell(0, "input_age_ms.2"), "", "past input_count: empty");
        assert_eq!(cell(0, "detail.1.name"), "rtt_ms");
        assert_eq!(cell(0, "detail.1.value"), "0.25");
        assert_eq!(cell(0, "detail.2.name"), "");
        assert_eq!(cell(1, "node"), "glove");
        assert_eq!(cell(1, "input_age_ms.4"), "4.5");
        assert_eq!(cell(1, "detail.7.name"), "d7");
        assert_eq!(cell(1, "detail.7.value"), "7.0");
        assert_eq!(cell(2, "detail.0.name"), "");
        assert_eq!(rows[3], rows[0]);
    }

    #[test]
    fn other_topics_show_their_fields_with_texts_and_without_reserved_bytes() {
        let mut ack = EStopAck {
            engaged: 1,
            node_name: teleop_msgs::fixed_text("left/feedback"),
            ..Default::default()
        };
        ack.header.seq = 4;
        ack.header.stamp_ns = 1_000;
        ack.reserved[0] = 5;
        let yaml = show(Format::Yaml, &ack);
        assert_eq!(
            yaml,
            "---\nheader: {seq: 4, stamp_ns: 1000, origin_ns: 0, source_id: 0}\nengaged: true\n\
             node_name: \"left/feedback\""
        );
        // The same header as the payloads shown by name.
        let estop = show(Format::Yaml, &EStop::default());
        let state = show(Format::Yaml, &HandState::default());
        assert_eq!(estop.lines().nth(1), state.lines().nth(1));
        assert_eq!(
            show(Format::Json, &EStop::default()),
            "{\"header\":{\"seq\":0,\"stamp_ns\":0,\"origin_ns\":0,\"source_id\":0},\"engaged\":false}"
        );
        let device = DeviceInfo {
            device_model: device_model::GLOVE,
            link_kind: link_kind::SERIAL,
            bus_address: 1,
            model_name: teleop_msgs::fixed_text("EH55BF1"),
            ..Default::default()
        };
        let yaml = show(Format::Yaml, &device);
        assert!(
            yaml.ends_with(
                "\ndevice_model: glove\nlink_kind: serial\nbus_address: \"1\"\n\
                 model_name: EH55BF1"
            ),
            "{yaml}"
        );
    }

    #[test]
    fn episodes_and_estops_show_their_values_by_name() {
        use teleop_msgs::{episode_event, episode_outcome, fixed_text};
        let mut mark = Episode {
            event: episode_event::START,
            task: fixed_text("pick up the cube"),
            ..Default::default()
        };
        let yaml = show(Format::Yaml, &mark);
        assert!(
            yaml.ends_with("\nevent: start\noutcome: unlabelled\ntask: \"pick up the cube\""),
            "{yaml}"
        );
        for (event, outcome, shown) in [
            (
                episode_event::STOP,
                episode_outcome::SUCCESS,
                "stop,success,",
            ),
            (
                episode_event::STOP,
                episode_outcome::FAILURE,
                "stop,failure,",
            ),
            (
                episode_event::DISCARD,
                episode_outcome::UNLABELLED,
                "discard,unlabelled,",
            ),
            (9, 7, "9,unlabelled,"),
        ] {
            mark.event = event;
            mark.outcome = outcome;
            mark.task = [0; teleop_msgs::EPISODE_TASK_BYTES];
            let (header, rows) = csv(&show(Format::Csv, &mark));
            assert_eq!(header[4..], ["event", "outcome", "task"], "{header:?}");
            assert_eq!(
                rows[0][4..].join(",") + ",",
                format!("{shown},"),
                "{event} {outcome}"
            );
        }
        let json = show(Format::Json, &mark);
        assert!(
            json.ends_with(",\"event\":9,\"outcome\":\"unlabelled\",\"task\":\"\"}"),
            "{json}"
        );

        let engaged = EStop {
            engaged: 1,
            ..Default::default()
        };
        assert!(show(Format::Yaml, &engaged).ends_with("\nengaged: true"));
        let odd = EStop {
            engaged: 2,
            ..Default::default()
        };
        assert!(
            show(Format::Yaml, &odd).ends_with("\nengaged: 2"),
            "not named: its number"
        );
    }

    #[test]
    fn a_profile_of_another_model_names_the_sample_with_one_warning() {
        // The LEAP's profile given, Allegro samples: named by the LEAP's joints, warned once.
        let leap = profile("leap");
        let s = state(&profile("allegro"));
        let mut echo = Echo::new(Format::Yaml, Some(leap.clone()));
        let shown = echo.show(&s);
        let names: Vec<String> = leap.joint_names().map(String::from).collect();
        assert_eq!(yaml_keys(&shown, "joints"), names, "{shown}");
        let warnings = echo.take_warnings();
        assert_eq!(warnings.len(), 1, "{warnings:?}");
        assert!(
            warnings[0].contains("hand model allegro (2)")
                && warnings[0].contains(&format!("{:?}", leap.name))
                && warnings[0].contains("model leap (5)"),
            "{warnings:?}"
        );
        echo.show(&s);
        assert!(echo.take_warnings().is_empty(), "said once");
        // Its own model: no warning.
        let mut echo = Echo::new(Format::Yaml, Some(leap.clone()));
        echo.show(&state(&leap));
        assert!(echo.take_warnings().is_empty());
    }

    #[test]
    fn a_csv_run_keeps_its_first_header_whatever_the_samples_use() {
        let revo2 = profile("revo2");
        let names: Vec<String> = revo2.joint_names().map(String::from).collect();
        let mut echo = Echo::new(Format::Csv, None);
        let full = state(&revo2);
        // Fewer joints used than the profile names; then another hand's sample (named by the
        // run's profile, warned); then more joints than the header has.
        let mut fewer = full;
        fewer.joint_count = 2;
        let other = state(&profile("allegro"));
        let text = [&fewer, &full, &other].map(|s| echo.show(s)).join("\n");
        let warnings = echo.take_warnings();
        assert_eq!(warnings.len(), 2, "{warnings:?}");
        assert!(
            warnings[0].contains("hand model allegro (2)"),
            "{warnings:?}"
        );
        assert!(warnings[0].contains("model revo2 (1)"), "{warnings:?}");
        assert!(
            warnings[1].contains("left out: joints.joint_6.position, joints.joint_6.speed, "),
            "{warnings:?}"
        );
        let (header, rows) = csv(&text);
        assert_eq!(rows.len(), 3, "one header: {text}");
        let joint_columns = joint_columns(&header);
        assert_eq!(
            joint_columns, names,
            "the profile's, from the first row: {text}"
        );
        let cell = |row: usize, column: String| {
            let at = header.iter().position(|c| *c == column).unwrap();
            rows[row][at].clone()
        };
        assert_eq!(cell(0, format!("joints.{}.position", names[1])), "0.1");
        for field in ["position", "speed", "effort_nm", "current_ma", "status"] {
            assert_eq!(
                cell(0, format!("joints.{}.{field}", names[2])),
                "",
                "unused"
            );
        }
        assert_eq!(cell(1, format!("joints.{}.position", names[2])), "0.2");
        assert_eq!(cell(2, format!("joints.{}.position", names[5])), "0.5");

        // Tactile: every field of every fingertip the profile names, whatever the sensor.
        let mut t = Tactile {
            hand_model: revo2.model_id,
            fingertip_count: 1,
            ..Default::default()
        };
        t.fingertips[0].sensor_kind = fingertip_sensor::REVO2_FORCE;
        t.fingertips[0].normal_n = 1.5;
        let mut echo = Echo::new(Format::Csv, None);
        let text = echo.show(&t);
        t.fingertip_count = 5;
        for f in &mut t.fingertips {
            f.sensor_kind = fingertip_sensor::PST_PRESSURE;
            f.pressure = 7;
        }
        let text = format!("{text}\n{}", echo.show(&t));
        assert!(echo.take_warnings().is_empty());
        let (header, rows) = csv(&text);
        assert_eq!(rows.len(), 2, "{text}");
        let tips: Vec<String> = revo2.fingertips().map(|f| f.name.clone()).collect();
        let cell = |row: usize, column: String| {
            let at = header.iter().position(|c| *c == column).unwrap();
            rows[row][at].clone()
        };
        assert_eq!(cell(0, format!("fingertips.{}.normal_n", tips[0])), "1.5");
        assert_eq!(cell(0, format!("fingertips.{}.pressure", tips[0])), "");
        assert_eq!(cell(0, format!("fingertips.{}.sensor", tips[1])), "");
        assert_eq!(cell(1, format!("fingertips.{}.normal_n", tips[0])), "");
        assert_eq!(cell(1, format!("fingertips.{}.pressure", tips[4])), "7");
        assert_eq!(
            cell(1, format!("fingertips.{}.sensor", tips[4])),
            "pst_pressure"
        );
    }

    #[test]
    fn floats_read_back_as_floats_and_texts_and_keys_are_quoted_where_needed() {
        for (value, text) in [
            (1e-7f32, "1.0e-7"),
            (1.5e20, "1.5e+20"),
            (0.1, "0.1"),
            (-2.0, "-2.0"),
        ] {
            assert_eq!(yaml_flow(&Value::F32(value)), text);
            let back: f32 = text.parse().unwrap();
            assert_eq!(back, value);
        }
        assert_eq!(yaml_flow(&Value::F64(f64::NEG_INFINITY)), "-.inf");
        assert_eq!(json(&Value::F64(f64::INFINITY)), "null");
        assert_eq!(yaml_text("on"), "\"on\"");
        assert_eq!(yaml_text("FFJ1"), "FFJ1");
        assert_eq!(yaml_text("a b"), "\"a b\"");
        assert_eq!(quoted("say \"hi\"\n"), "\"say \\\"hi\\\"\\n\"");
        assert_eq!(csv_cell("a,\"b\""), "\"a,\"\"b\"\"\"");
    }
}
