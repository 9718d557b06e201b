//! `teleop reprocess` retargets with the hand the recording was made with: the profile embedded
//! in its metadata, or for recordings made before profiles the shipped profile of its hand model.
#![allow(clippy::unwrap_used)]

use std::collections::BTreeMap;

use teleop_e2e::Sandbox;
use teleop_msgs::{device_model, units, GloveState, HandCommand, Message};
use teleop_recording::{read_messages, Filter, RecordedMessage, Recorder, WriterOptions};

fn sample() -> std::path::PathBuf {
    Sandbox::repo().join("recordings/grasp.sample.mcap")
}

/// The hand commands of a reprocessed file.
fn commands(path: &std::path::Path) -> Vec<HandCommand> {
    read_messages(path, &Filter::topics([HandCommand::TOPIC]))
        .unwrap()
        .map(|m| m.unwrap().decode::<HandCommand>().unwrap())
        .collect()
}

/// A recorder whose file embeds the profile at `profile` as the recorder does.
fn recorder_with_profile(path: &std::path::Path, profile: &std::path::Path) -> Recorder {
    let metadata = vec![(
        "hand_profile".to_string(),
        BTreeMap::from([
            ("file".to_string(), profile.display().to_string()),
            (
                "text".to_string(),
                std::fs::read_to_string(profile).unwrap(),
            ),
        ]),
    )];
    Recorder::create(path, WriterOptions::default(), &metadata).unwrap()
}

#[test]
fn the_profile_embedded_in_a_recording_drives_reprocessing() {
    let sandbox = Sandbox::new();
    // An operator recording (the sample's glove samples) made with the Allegro profile.
    let profile = Sandbox::repo().join("config/hands/allegro.toml");
    let input = sandbox.dir.path().join("allegro-session.mcap");
    let mut rec = recorder_with_profile(&input, &profile);
    let glove = rec.add_message_type::<GloveState>().unwrap();
    let mut n = 0;
    for m in read_messages(&sample(), &Filter::topics([GloveState::TOPIC])).unwrap() {
        let m = m.unwrap();
        let s: GloveState = m.decode().unwrap();
        rec.write(glove, &RecordedMessage::from_sample(&s, m.log_time_ns))
            .unwrap();
        n += 1;
    }
    rec.finish().unwrap();

    let out = sandbox.dir.path().join("out.mcap");
    let r = sandbox.run_teleop(&[
        "reprocess",
        input.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{stderr}");
    assert!(
        stderr.contains("hand profile `allegro` from the recording's metadata"),
        "{stderr}"
    );
    let cmds = commands(&out);
    assert_eq!(cmds.len(), n);
    for c in &cmds {
        assert_eq!(c.hand_model, device_model::ALLEGRO);
        assert_eq!(c.joint_count, 16);
        assert_eq!(c.units, units::PHYSICAL);
    }

    // The Revo2 retargeting configuration names Revo2 joints: refused for this hand, by name.
    let r = sandbox.run_teleop(&[
        "reprocess",
        input.to_str().unwrap(),
        "--out",
        sandbox.dir.path().join("refused.mcap").to_str().unwrap(),
        "--retarget-config",
        Sandbox::repo()
            .join("config/revo2/retarget.toml")
            .to_str()
            .unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert!(!r.status.success());
    assert!(
        stderr.contains("retarget.toml:") && stderr.contains("has no joint"),
        "{stderr}"
    );
}

#[test]
fn reprocessing_onto_its_own_input_is_refused_and_keeps_the_recording() {
    let sandbox = Sandbox::new();
    let copy = sandbox.dir.path().join("session.mcap");
    std::fs::copy(sample(), &copy).unwrap();
    let before = std::fs::read(&copy).unwrap();
    // The same file, also through another spelling of its path.
    let other = sandbox.dir.path().join(".").join("session.mcap");
    for out in [&copy, &other] {
        let r = sandbox.run_teleop(&[
            "reprocess",
            copy.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        let stderr = String::from_utf8_lossy(&r.stderr);
        assert!(!r.status.success());
        assert!(
            stderr.contains("is the recording being reprocessed"),
            "{stderr}"
        );
        assert_eq!(
            std::fs::read(&copy).unwrap(),
            before,
            "the recording is intact"
        );
    }
}

#[test]
fn a_recording_without_a_profile_uses_the_shipped_profile_of_its_hand() {
    let sandbox = Sandbox::new();
    let out = sandbox.dir.path().join("out.mcap");
    let r = sandbox.run_teleop(&[
        "reprocess",
        sample().to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{stderr}");
    assert!(stderr.contains("hand profile `revo2` (shipped"), "{stderr}");
    let cmds = commands(&out);
    assert!(cmds.len() > 1000);
    assert!(cmds
        .iter()
        .all(|c| c.hand_model == device_model::REVO2 && c.joint_count == 6));
}

#[test]
fn one_side_of_a_two_sided_recording_is_reprocessed_with_namespace() {
    let sandbox = Sandbox::new();
    let profile = Sandbox::repo().join("config/hands/revo2.toml");
    let input = sandbox.dir.path().join("bimanual.mcap");
    let mut rec = recorder_with_profile(&input, &profile);
    let left = rec
        .add_topic(
            "left/glove/state",
            GloveState::SCHEMA_NAME,
            &GloveState::schema(),
        )
        .unwrap();
    let right = rec
        .add_topic(
            "right/glove/state",
            GloveState::SCHEMA_NAME,
            &GloveState::schema(),
        )
        .unwrap();
    let mut n = 0;
    for m in read_messages(&sample(), &Filter::topics([GloveState::TOPIC])).unwrap() {
        let m = m.unwrap();
        let s: GloveState = m.decode().unwrap();
        // The left operator grasps as recorded; the right one keeps the hand open.
        let open = GloveState {
            raw_position: [1000; 6],
            ..s
        };
        for (id, topic, sample) in [
            (left, "left/glove/state", &s),
            (right, "right/glove/state", &open),
        ] {
            let msg = RecordedMessage {
                topic,
                ..RecordedMessage::from_sample(sample, m.log_time_ns)
            };
            rec.write(id, &msg).unwrap();
        }
        n += 1;
    }
    rec.finish().unwrap();

    let reprocess = |args: &[&str]| {
        let out = sandbox.dir.path().join("out.mcap");
        let mut all = vec![
            "reprocess",
            input.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        all.extend_from_slice(args);
        let r = sandbox.run_teleop(&all);
        (r, out)
    };
    let closes = |cmds: &[HandCommand]| cmds.iter().any(|c| c.joints[2].target > 0.3);
    let (r, out) = reprocess(&["--namespace", "left"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let cmds = commands(&out);
    assert_eq!(cmds.len(), n);
    assert!(closes(&cmds), "the left operator closes the hand");
    let (r, out) = reprocess(&["--namespace", "right"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let cmds = commands(&out);
    assert_eq!(cmds.len(), n);
    assert!(!closes(&cmds), "the right operator keeps it open");
    // Without a side, or with one that is not there: refused, naming the sides there are.
    for args in [&[][..], &["--namespace", "top"][..]] {
        let (r, _) = reprocess(args);
        let stderr = String::from_utf8_lossy(&r.stderr);
        assert!(!r.status.success());
        assert!(
            stderr.contains("choose a side with --namespace (left, right)"),
            "{stderr}"
        );
    }
}
