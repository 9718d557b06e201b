//! `teleop echo` against running hand nodes (issue 25): for each shipped hand (Revo2, Allegro,
//! Shadow, LEAP) running against its simulator, `teleop echo` of `hand/state`, `hand/command`
//! (published by the test) and, for hands with fingertip sensors, `hand/tactile`, in YAML, JSON
//! and CSV, names the used joints and fingertips by the hand profile, in the profile's order,
//! and nothing else; `health` names the node. Given another hand's profile file (`--profile`),
//! it names the joints by that profile (numbered past its joints) and warns once on standard
//! error that the models differ; otherwise it warns of nothing.
//!
//! The values are checked under their names, so that a name put on another joint's value is
//! caught: the test commands each joint a target of its own (a fraction of its range that no
//! other joint gets, within the profile's limits so that admission changes nothing), and
//! `hand/command`'s echo must show each joint's target under its name; `hand/state`'s must show
//! under each name the position the test itself received for that joint in the sample of the
//! same `header.seq`, the hand having first been driven until neighbouring joints' positions
//! differ (a name on its neighbour's value shows; the Shadow Hand's J1s follow their J2s and
//! are left out of that: a J1 and its J2 may show the same value).
//!
//! Python reads the three outputs back (PyYAML, `json`, `csv.DictReader`: readers that are not
//! ours; PyYAML is in `.ci/requirements.txt`) and says, for every sample, its `header.seq` and
//! each entry's name and value (a CSV row's values under the columns of the one header, a
//! second header would be a row whose `header.seq` is no number); this test reads them itself
//! too (the JSON with serde_json, the YAML and CSV lines by hand) and checks both.
#![allow(clippy::unwrap_used)]

use std::collections::BTreeMap;
use std::io::Read;
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

use teleop_e2e::hand::{one_at_a_time, HandNode};
use teleop_hand_node::{Admission, Modes};
use teleop_hand_profile::{CommandUnits, HandProfile};
use teleop_msgs::{control_mode, HandCommand, HandState};

/// Samples each `teleop echo` prints.
const SAMPLES: usize = 3;

/// The least difference between two joints' targets, in the command's units: several of the
/// simulators' position steps (the LEAP's is 2π/4096 rad), so that the joints' positions differ
/// too once they follow.
const APART: f32 = 0.01;

#[test]
fn echo_names_the_revo2s_joints_and_fingertips() {
    echo_names("revo2");
}

#[test]
fn echo_names_the_allegros_joints() {
    echo_names("allegro");
}

#[test]
fn echo_names_the_shadow_hands_joints_and_fingertips() {
    echo_names("shadow");
}

#[test]
fn echo_names_the_leap_hands_joints() {
    echo_names("leap");
}

/// A topic echoed: its table of named entries and, if its values are checked, the field
/// compared under each entry.
struct Topic<'a> {
    name: &'a str,
    table: &'a str,
    names: &'a [String],
    field: Option<&'a str>,
}

/// What each entry of a sample must hold in the checked field, in the entries' order.
enum Values {
    /// The same in every sample: the command the test publishes.
    Same(Vec<f32>),
    /// Each sample's own, as the test received it, by `header.seq`.
    BySeq(BTreeMap<u64, Vec<f32>>),
}

impl Values {
    fn of(&self, seq: u64) -> Option<&[f32]> {
        match self {
            Values::Same(v) => Some(v),
            Values::BySeq(by_seq) => by_seq.get(&seq).map(Vec::as_slice),
        }
    }
}

/// One sample as read back from an output: its `header.seq` and each entry of the table with
/// the checked field's value (`None` when not checked, empty or missing).
#[derive(Debug, serde::Deserialize)]
struct Shown {
    seq: u64,
    entries: Vec<(String, Option<f64>)>,
}

/// `hand`'s node against its simulator; every hand topic in every format names what the
/// profile names, and shows each joint's value under its name.
fn echo_names(hand: &str) {
    let _turn = one_at_a_time();
    let mut node = HandNode::simulated(hand);
    let profile = HandProfile::builtin(hand).unwrap();
    let joints: Vec<String> = profile.joint_names().map(String::from).collect();
    let fingertips: Vec<String> = profile.fingertips().map(|f| f.name.clone()).collect();
    let command = distinct_command(&profile);
    let targets: Vec<f32> = command.active_joints().iter().map(|j| j.target).collect();
    // The joints whose values must differ in every sample checked: each joint that follows
    // no other and the next such joint.
    let free: Vec<usize> = (0..joints.len())
        .filter(|&i| profile.joints[i].coupling.is_none())
        .collect();
    let neighbours: Vec<(usize, usize)> = free.windows(2).map(|w| (w[0], w[1])).collect();

    let mut topics = vec![
        Topic {
            name: "hand/command",
            table: "joints",
            names: &joints,
            field: Some("target"),
        },
        Topic {
            name: "hand/state",
            table: "joints",
            names: &joints,
            field: Some("position"),
        },
    ];
    if !fingertips.is_empty() {
        topics.push(Topic {
            name: "hand/tactile",
            table: "fingertips",
            names: &fingertips,
            field: None,
        });
    }
    for topic in topics {
        let mut received: BTreeMap<u64, Vec<f32>> = BTreeMap::new();
        if topic.name == "hand/state" {
            // The newest state so far, which the first echo may show.
            let s = drive_apart(&mut node, &command, &neighbours);
            received.insert(s.header.seq, positions(&s));
        }
        let mut outputs: Vec<(&str, String)> = Vec::new();
        for format in ["yaml", "json", "csv"] {
            let text = echo(&mut node, topic.name, format, |node| {
                // Published while `teleop echo` waits: its samples for `hand/command`, the
                // hand kept on its targets for `hand/state`.
                node.commands.publish(&command).unwrap();
                node.states.drain(|s| {
                    received.insert(s.header.seq, positions(s));
                });
            });
            outputs.push((format, text));
        }
        let values = match topic.name {
            "hand/command" => Values::Same(targets.clone()),
            _ => Values::BySeq(received),
        };
        let what = format!("{hand}: teleop echo {topic}", topic = topic.name);
        let field = topic.field.unwrap_or("");
        let ours = [
            ("yaml", read_yaml(&what, &outputs[0].1, topic.table, field)),
            ("json", read_json(&what, &outputs[1].1, topic.table, field)),
            ("csv", read_csv(&what, &outputs[2].1, topic.table, field)),
        ];
        for (format, shown) in ours {
            check(&what, format, &shown, &topic, &values, &neighbours);
        }
        for (format, shown) in read_by_python(&what, &outputs, topic.table, field) {
            let what = format!("{what}, read by Python");
            check(&what, &format, &shown, &topic, &values, &neighbours);
        }
    }

    // A profile of another hand given: it names the joints (numbered past its own), with one
    // warning that the models differ.
    let other = if hand == "allegro" { "leap" } else { "allegro" };
    let file = teleop_e2e::Sandbox::repo().join(format!("config/hands/{other}.toml"));
    let samples = SAMPLES.to_string();
    let file = file.display().to_string();
    let args = ["echo", "hand/command", "-n", &samples, "--profile", &file];
    let (yaml, err) = run_echo(&mut node, &args, |node| {
        node.commands.publish(&command).unwrap();
    });
    let given = HandProfile::builtin(other).unwrap();
    let other_names: Vec<String> = (0..joints.len())
        .map(|i| {
            given
                .joints
                .get(i)
                .map_or(format!("joint_{i}"), |j| j.name.clone())
        })
        .collect();
    let what = format!("{hand}: teleop echo hand/command --profile {other}.toml");
    assert_eq!(err.matches("warning: ").count(), 1, "{what}: {err}");
    assert!(
        err.contains(&format!("is named by the profile given, \"{other}\"")),
        "{what}: {err}"
    );
    let topic = Topic {
        name: "hand/command",
        table: "joints",
        names: &other_names,
        field: Some("target"),
    };
    let shown = read_yaml(&what, &yaml, "joints", "target");
    check(
        &what,
        "yaml",
        &shown,
        &topic,
        &Values::Same(targets),
        &neighbours,
    );

    // Health: the node by name.
    let health = echo(&mut node, "health", "json", |_| {});
    let line = health.lines().next().unwrap();
    let report: serde_json::Value = serde_json::from_str(line).unwrap();
    assert_eq!(report["node"], hand, "{health}");
    assert!(report["loop_rate_hz"].as_f64().is_some(), "{health}");
}

/// A position command for `profile`'s hand, in its command units, giving each joint a target
/// of its own: joint `i` of `n` moves from its open angle the fraction `(i + 1) / (4 (n + 1))`
/// of the way to its closed angle (to its upper limit for a joint whose open and closed angles
/// are the same, a spreading joint), a little further while that comes within [`APART`] of an
/// earlier joint's target: a hand a little closed, whose fingers meet no simulated object.
/// Checked to be one admission leaves as it is and to have no two joints with the same target.
fn distinct_command(profile: &HandProfile) -> HandCommand {
    let admission = Admission::new(profile, Modes::POSITION);
    let n = admission.joints();
    let mut command = HandCommand {
        hand_model: admission.model(),
        joint_count: n as u8,
        control_mode: control_mode::POSITION,
        units: admission.units(),
        ..Default::default()
    };
    let mut targets: Vec<f32> = Vec::new();
    for (i, joint) in profile.joints.iter().enumerate() {
        let towards = if joint.closed != joint.open {
            joint.closed
        } else {
            joint.upper
        };
        let step = 1.0 / (4 * (n + 1)) as f32;
        let mut fraction = (i + 1) as f32 * step;
        let target = loop {
            let radians = joint.open + (towards - joint.open) * fraction;
            let target = match profile.command_units {
                CommandUnits::Radians => radians,
                CommandUnits::Normalised => joint.normalised(radians),
            };
            if targets.iter().all(|t| (t - target).abs() >= APART) {
                break target;
            }
            fraction += step / 8.0;
        };
        targets.push(target);
    }
    for (c, t) in command.joints.iter_mut().zip(&targets) {
        c.target = *t;
    }
    let mut admitted = command;
    assert_eq!(
        admission.admit(&mut admitted, None),
        Ok(0),
        "{}: targets within the limits",
        profile.name
    );
    assert_eq!(admitted, command);
    let targets: Vec<f32> = command.active_joints().iter().map(|j| j.target).collect();
    let every_pair: Vec<(usize, usize)> = (0..n)
        .flat_map(|i| (i + 1..n).map(move |k| (i, k)))
        .collect();
    assert_differ(&profile.name, &targets, &every_pair);
    command
}

/// The used joints' positions of a hand state.
fn positions(s: &HandState) -> Vec<f32> {
    s.active_joints().iter().map(|j| j.position).collect()
}

/// Panics (naming `what`) unless the values of each pair of joints differ.
fn assert_differ(what: &str, values: &[f32], pairs: &[(usize, usize)]) {
    if let Some((i, k)) = alike(values, pairs) {
        panic!("{what}: joints {i} and {k} have the same value: {values:?}");
    }
}

/// The first pair of joints whose values are the same.
fn alike(values: &[f32], pairs: &[(usize, usize)]) -> Option<(usize, usize)> {
    pairs.iter().copied().find(|&(i, k)| values[i] == values[k])
}

/// Sends `command` until the newest hand state has different positions at each pair of
/// joints (up to 20 s, then a panic with the logs), and returns that state.
fn drive_apart(node: &mut HandNode, command: &HandCommand, pairs: &[(usize, usize)]) -> HandState {
    let start = Instant::now();
    loop {
        let s = node.send(command, Duration::from_millis(50));
        let p = positions(&s);
        if alike(&p, pairs).is_none() {
            return s;
        }
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "the joints' positions stay alike: {p:?}\n{}",
            node.log()
        );
    }
}

/// The output of `teleop echo TOPIC -n SAMPLES --format FORMAT`, which warns of nothing,
/// calling `meanwhile` every 10 ms until it ends (a panic with the logs after 20 s).
fn echo(
    node: &mut HandNode,
    topic: &str,
    format: &str,
    meanwhile: impl FnMut(&mut HandNode),
) -> String {
    let samples = SAMPLES.to_string();
    let args = ["echo", topic, "-n", &samples, "--format", format];
    let (out, err) = run_echo(node, &args, meanwhile);
    assert!(!err.contains("warning"), "teleop echo {topic}: {err}");
    out
}

/// The standard output and error of `teleop ARGS` (a `teleop echo`), which must succeed,
/// calling `meanwhile` every 10 ms until it ends (a panic with the logs after 20 s).
fn run_echo(
    node: &mut HandNode,
    args: &[&str],
    mut meanwhile: impl FnMut(&mut HandNode),
) -> (String, String) {
    let command = args.join(" ");
    let mut child: Child = node
        .rig
        .sandbox
        .teleop()
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if start.elapsed() > Duration::from_secs(20) {
            child.kill().unwrap();
            child.wait().unwrap();
            panic!(
                "teleop {command}: no {SAMPLES} samples in 20 s\n{}",
                node.log()
            );
        }
        meanwhile(node);
        std::thread::sleep(Duration::from_millis(10));
    };
    // The samples published until it ended.
    meanwhile(node);
    let mut out = String::new();
    child
        .stdout
        .take()
        .unwrap()
        .read_to_string(&mut out)
        .unwrap();
    let mut err = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    assert!(status.success(), "teleop {command}: {status}\n{out}{err}");
    (out, err)
}

/// Every sample of every format: `SAMPLES` of them, each with the table's entries named
/// `names` in that order and only those, and, where the field is checked, under each name
/// that joint's value ([`Values`]); the expected values of each pair of joints `apart`
/// differ, so that a name on the other's value cannot pass.
fn check(
    what: &str,
    format: &str,
    shown: &[Shown],
    topic: &Topic,
    values: &Values,
    apart: &[(usize, usize)],
) {
    let what = format!("{what} --format {format}");
    assert_eq!(shown.len(), SAMPLES, "{what}: {shown:?}");
    for sample in shown {
        assert!(sample.seq > 0, "{what}: {sample:?}");
        let names: Vec<&str> = sample.entries.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, topic.names, "{what}");
        let Some(field) = topic.field else {
            continue;
        };
        let expected = values
            .of(sample.seq)
            .unwrap_or_else(|| panic!("{what}: the test received no sample {}", sample.seq));
        assert_differ(&what, expected, apart);
        for ((name, value), want) in sample.entries.iter().zip(expected) {
            assert_eq!(
                value.map(|v| v as f32),
                Some(*want),
                "{what}, sample {}: {name}'s {field}",
                sample.seq
            );
        }
    }
}

/// The `field:` value in a YAML flow table (`{position: 0.5, speed: 0.0}`).
fn flow_value(flow: &str, field: &str) -> Option<f64> {
    flow.trim_start_matches('{')
        .trim_end_matches('}')
        .split(", ")
        .find_map(|kv| kv.strip_prefix(field)?.strip_prefix(": "))
        .and_then(|v| v.parse().ok())
}

/// The YAML documents (starting `---`), each's `header.seq` and the entries under `table:`.
fn read_yaml(what: &str, yaml: &str, table: &str, field: &str) -> Vec<Shown> {
    assert!(yaml.starts_with("---\nheader: {seq: "), "{what}:\n{yaml}");
    yaml.split("---\n")
        .skip(1)
        .map(|document| {
            let seq = document
                .strip_prefix("header: {seq: ")
                .and_then(|rest| rest.split(',').next()?.parse().ok())
                .unwrap_or_else(|| panic!("{what}: no header.seq in\n{document}"));
            let entries = document
                .lines()
                .skip_while(|l| *l != format!("{table}:"))
                .skip(1)
                .take_while(|l| l.starts_with("  "))
                .filter_map(|l| l.trim_start().split_once(": "))
                .map(|(name, flow)| (name.to_string(), flow_value(flow, field)))
                .collect();
            Shown { seq, entries }
        })
        .collect()
}

/// The JSON lines, each's `header.seq` and the entries of its object `table` in the order
/// written (serde_json keeps no order: the order of the names in the line).
fn read_json(what: &str, json: &str, table: &str, field: &str) -> Vec<Shown> {
    json.lines()
        .map(|line| {
            let sample: serde_json::Value =
                serde_json::from_str(line).unwrap_or_else(|e| panic!("{what}: {e}: {line}"));
            let object = sample[table].as_object().unwrap();
            let mut entries: Vec<(String, Option<f64>)> = object
                .iter()
                .map(|(name, v)| (name.clone(), v[field].as_f64()))
                .collect();
            entries.sort_by_key(|(name, _)| line.find(&format!("\"{name}\":{{")).unwrap());
            Shown {
                seq: sample["header"]["seq"].as_u64().unwrap(),
                entries,
            }
        })
        .collect()
}

/// The CSV: one header line and rows of as many cells; each row's `header.seq` and the
/// entries named by the header's `<table>.<name>.` columns, each's value the row's cell under
/// `<table>.<name>.<field>`.
fn read_csv(what: &str, csv: &str, table: &str, field: &str) -> Vec<Shown> {
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
    let prefix = format!("{table}.");
    let mut names: Vec<&str> = header
        .iter()
        .filter_map(|c| c.strip_prefix(&prefix)?.split_once('.').map(|(n, _)| n))
        .collect();
    names.dedup();
    let column = |name: &str| header.iter().position(|c| *c == name);
    lines
        .map(|row| {
            let cells: Vec<&str> = row.split(',').collect();
            assert_eq!(cells.len(), header.len(), "{what}:\n{csv}");
            let seq = column("header.seq")
                .and_then(|at| cells[at].parse().ok())
                .unwrap_or_else(|| panic!("{what}: no header.seq in {row}\n{csv}"));
            let entries = names
                .iter()
                .map(|name| {
                    let value = column(&format!("{table}.{name}.{field}"))
                        .and_then(|at| cells[at].parse().ok());
                    (name.to_string(), value)
                })
                .collect();
            Shown { seq, entries }
        })
        .collect()
}

/// Python reads the YAML documents, the JSON lines and the CSV rows and says, for each sample
/// of each format, its `header.seq` and the entries of its table, in order, with the value of
/// `field` under each; `None` where Python 3 with PyYAML is missing (a skip, a failure under
/// `TELEOP_REQUIRE_CHECKS`).
fn read_by_python(
    what: &str,
    outputs: &[(&str, String)],
    table: &str,
    field: &str,
) -> Vec<(String, Vec<Shown>)> {
    const READ: &str = r#"
import csv, io, json, sys
import yaml
table, field = sys.argv[1], sys.argv[2]
texts = json.load(sys.stdin)

def entries(sample):
    return [[name, value.get(field)] for name, value in sample[table].items()]

seen = {
    "yaml": [{"seq": d["header"]["seq"], "entries": entries(d)}
             for d in yaml.safe_load_all(texts["yaml"])],
    "json": [{"seq": s["header"]["seq"], "entries": entries(s)}
             for s in map(json.loads, texts["json"].splitlines())],
}
reader = csv.DictReader(io.StringIO(texts["csv"]))
names = []
for column in reader.fieldnames:
    parts = column.split(".")
    if parts[0] == table and parts[1] not in names:
        names.append(parts[1])
seen["csv"] = []
for row in reader:
    assert None not in row, "a row longer than the header: %r" % row
    def value(name):
        cell = row.get("%s.%s.%s" % (table, name, field), "")
        return float(cell) if cell != "" else None
    # A second header line would be a row whose header.seq is no number.
    seen["csv"].append({"seq": int(row["header.seq"]),
                        "entries": [[name, value(name)] for name in names]})
print(json.dumps(seen))
"#;
    let probe = std::process::Command::new("python3")
        .args(["-c", "import yaml"])
        .output();
    if !probe.is_ok_and(|o| o.status.success()) {
        teleop_e2e::netns::skip("Python 3 with PyYAML (pip install -r .ci/requirements.txt)");
        return Vec::new();
    }
    let texts: serde_json::Map<String, serde_json::Value> = outputs
        .iter()
        .map(|(format, text)| (format.to_string(), text.clone().into()))
        .collect();
    let mut python = std::process::Command::new("python3")
        .args(["-c", READ, table, field])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    {
        use std::io::Write;
        let mut stdin = python.stdin.take().unwrap();
        stdin
            .write_all(serde_json::Value::Object(texts).to_string().as_bytes())
            .unwrap();
    }
    let out = python.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{what}: Python could not read the output: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut seen: BTreeMap<String, Vec<Shown>> = serde_json::from_slice(&out.stdout).unwrap();
    ["yaml", "json", "csv"]
        .into_iter()
        .map(|format| (format.to_string(), seen.remove(format).unwrap_or_default()))
        .collect()
}
