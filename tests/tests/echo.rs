//! `teleop echo` against running hand nodes (issue 25): for each shipped hand (Revo2, Allegro,
//! Shadow, LEAP) running against its simulator, `teleop echo` of `hand/state`, `hand/command`
//! (published by the test) and, for hands with fingertip sensors, `hand/tactile`, in YAML, JSON
//! and CSV, names the used joints and fingertips by the hand profile, in the profile's order,
//! and nothing else; `health` names the node. Python reads the three outputs back (PyYAML,
//! `json`, `csv`: readers that are not ours; PyYAML is in `.ci/requirements.txt`), and this test
//! reads the JSON with serde_json and the CSV header itself.
#![allow(clippy::unwrap_used)]

use std::io::Read;
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

use teleop_e2e::hand::{one_at_a_time, position_command, HandNode};
use teleop_hand_profile::HandProfile;

/// Samples each `teleop echo` prints.
const SAMPLES: usize = 3;

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

/// `hand`'s node against its simulator; every hand topic in every format names what the
/// profile names.
fn echo_names(hand: &str) {
    let _turn = one_at_a_time();
    let mut node = HandNode::simulated(hand);
    let profile = HandProfile::builtin(hand).unwrap();
    let joints: Vec<String> = profile.joint_names().map(String::from).collect();
    let fingertips: Vec<String> = profile.fingertips().map(|f| f.name.clone()).collect();
    // A command the test publishes while `teleop echo hand/command` waits for samples.
    let command = position_command(profile.model_id, &vec![0.0; joints.len()]);

    let mut topics = vec![
        ("hand/state", "joints", &joints),
        ("hand/command", "joints", &joints),
    ];
    if !fingertips.is_empty() {
        topics.push(("hand/tactile", "fingertips", &fingertips));
    }
    for (topic, table, names) in topics {
        let outputs: Vec<(&str, String)> = ["yaml", "json", "csv"]
            .into_iter()
            .map(|format| {
                let text = echo(&mut node, topic, format, |node| {
                    if topic == "hand/command" {
                        node.commands.publish(&command).unwrap();
                    }
                });
                (format, text)
            })
            .collect();
        let what = format!("{hand}: teleop echo {topic}");
        check_yaml(&what, &outputs[0].1, table, names);
        check_json(&what, &outputs[1].1, table, names);
        check_csv(&what, &outputs[2].1, table, names);
        read_by_python(&what, &outputs, table, names);
    }

    // Health: the node by name.
    let health = echo(&mut node, "health", "json", |_| {});
    let line = health.lines().next().unwrap();
    let report: serde_json::Value = serde_json::from_str(line).unwrap();
    assert_eq!(report["node"], hand, "{health}");
    assert!(report["loop_rate_hz"].as_f64().is_some(), "{health}");
}

/// The output of `teleop echo TOPIC -n SAMPLES --format FORMAT`, calling `meanwhile` every
/// 10 ms until it ends (a panic with the logs after 20 s).
fn echo(
    node: &mut HandNode,
    topic: &str,
    format: &str,
    mut meanwhile: impl FnMut(&mut HandNode),
) -> String {
    let mut child: Child = node
        .rig
        .sandbox
        .teleop()
        .args([
            "echo",
            topic,
            "-n",
            &SAMPLES.to_string(),
            "--format",
            format,
        ])
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
                "teleop echo {topic} --format {format}: no {SAMPLES} samples in 20 s\n{}",
                node.log()
            );
        }
        meanwhile(node);
        std::thread::sleep(Duration::from_millis(10));
    };
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
    assert!(
        status.success(),
        "teleop echo {topic} --format {format}: {status}\n{out}{err}"
    );
    out
}

/// `SAMPLES` documents, each with the table's entries named `names`, in that order, and only
/// those.
fn check_yaml(what: &str, yaml: &str, table: &str, names: &[String]) {
    let documents: Vec<&str> = yaml.split("---\n").skip(1).collect();
    assert_eq!(documents.len(), SAMPLES, "{what}:\n{yaml}");
    assert!(yaml.starts_with("---\nheader: {seq: "), "{what}:\n{yaml}");
    for document in documents {
        let entries: Vec<&str> = document
            .lines()
            .skip_while(|l| *l != format!("{table}:"))
            .skip(1)
            .take_while(|l| l.starts_with("  "))
            .filter_map(|l| l.trim_start().split_once(": ").map(|(k, _)| k))
            .collect();
        assert_eq!(entries, names, "{what}:\n{document}");
    }
}

/// `SAMPLES` lines, each a JSON object whose table has exactly the entries `names` (serde_json
/// keeps no order; Python checks it).
fn check_json(what: &str, json: &str, table: &str, names: &[String]) {
    let lines: Vec<&str> = json.lines().collect();
    assert_eq!(lines.len(), SAMPLES, "{what}:\n{json}");
    for line in lines {
        let sample: serde_json::Value = serde_json::from_str(line).unwrap();
        let mut entries: Vec<&String> = sample[table].as_object().unwrap().keys().collect();
        let mut expected: Vec<&String> = names.iter().collect();
        entries.sort();
        expected.sort();
        assert_eq!(entries, expected, "{what}:\n{line}");
        assert!(sample["header"]["seq"].as_u64().unwrap() > 0, "{line}");
    }
}

/// A header line and `SAMPLES` rows of as many cells, the table's columns named by `names` in
/// order.
fn check_csv(what: &str, csv: &str, table: &str, names: &[String]) {
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 1 + SAMPLES, "{what}:\n{csv}");
    let header: Vec<&str> = lines[0].split(',').collect();
    for row in &lines[1..] {
        assert_eq!(row.split(',').count(), header.len(), "{what}:\n{csv}");
    }
    let prefix = format!("{table}.");
    let mut entries: Vec<&str> = header
        .iter()
        .filter_map(|c| {
            c.strip_prefix(&prefix)?
                .split_once('.')
                .map(|(name, _)| name)
        })
        .collect();
    entries.dedup();
    assert_eq!(entries, names, "{what}:\n{}", lines[0]);
}

/// Python reads the YAML documents, the JSON lines and the CSV rows, and says which entries
/// each sample's table has, in order; every sample of every format must have `names`.
fn read_by_python(what: &str, outputs: &[(&str, String)], table: &str, names: &[String]) {
    const READ: &str = r#"
import csv, io, json, sys
import yaml
table = sys.argv[1]
texts = json.load(sys.stdin)
seen = {
    "yaml": [list(d[table]) for d in yaml.safe_load_all(texts["yaml"])],
    "json": [list(json.loads(l)[table]) for l in texts["json"].splitlines()],
}
rows = list(csv.DictReader(io.StringIO(texts["csv"])))
names = []
for column in rows[0]:
    parts = column.split(".")
    if parts[0] == table and parts[1] not in names:
        names.append(parts[1])
seen["csv"] = [names for _ in rows]
print(json.dumps(seen))
"#;
    let probe = std::process::Command::new("python3")
        .args(["-c", "import yaml"])
        .output();
    if !probe.is_ok_and(|o| o.status.success()) {
        teleop_e2e::netns::skip("Python 3 with PyYAML (pip install -r .ci/requirements.txt)");
        return;
    }
    let texts: serde_json::Map<String, serde_json::Value> = outputs
        .iter()
        .map(|(format, text)| (format.to_string(), text.clone().into()))
        .collect();
    let mut python = std::process::Command::new("python3")
        .args(["-c", READ, table])
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
    let seen: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for format in ["yaml", "json", "csv"] {
        let samples = seen[format].as_array().unwrap();
        assert_eq!(samples.len(), SAMPLES, "{what} --format {format}: {seen}");
        for sample in samples {
            let entries: Vec<&str> = sample
                .as_array()
                .unwrap()
                .iter()
                .map(|n| n.as_str().unwrap())
                .collect();
            assert_eq!(entries, names, "{what} --format {format}, read by Python");
        }
    }
}
