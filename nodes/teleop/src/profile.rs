//! `teleop profile`: the hand profiles as other tools want them.
//!
//! * `teleop profile list`: the builtin profiles (name, model, joints).
//! * `teleop profile urdf HAND_OR_FILE [--out FILE]`: the profile as URDF (to standard output,
//!   or written to FILE), for RViz, MuJoCo, Isaac, pinocchio or dex-retargeting. HAND_OR_FILE is
//!   a builtin name (`teleop profile list`) or the path of a profile TOML. The frames, joint
//!   names and placeholder values of the URDF are described in `teleop_hand_profile::urdf`:
//!   the root link `wrist` is the hand frame, each profile joint is the URDF joint of its name,
//!   linkages and couplings are `<mimic>` joints, and each finger has `<finger>_tip` and
//!   `<finger>_pad` frames.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use clap::Subcommand;
use teleop_hand_profile::HandProfile;

/// `teleop profile ...`.
#[derive(Subcommand)]
pub enum ProfileCommand {
    /// The builtin hand profiles: name, model and joints.
    List,
    /// Export a hand profile as URDF (for RViz, MuJoCo, Isaac, pinocchio, dex-retargeting).
    ///
    /// `teleop profile urdf shadow --out shadow.urdf`. The root link `wrist` is the hand frame;
    /// each profile joint is the revolute joint of its name, with its limits; linkage-driven
    /// links (the Revo2's distal phalanges) and coupled joints (the Shadow Hand's J1) are
    /// `<mimic>` joints; each finger has `<finger>_tip` and `<finger>_pad` frames (the pad with
    /// a collision sphere of the pad's radius). Effort, velocity and link masses are
    /// placeholders, not datasheet figures.
    Urdf {
        /// A builtin profile name (`teleop profile list`) or a profile TOML file.
        #[arg(value_name = "HAND_OR_FILE")]
        hand: String,
        /// Write the URDF to this file (replaced if it exists) instead of standard output.
        #[arg(long)]
        out: Option<PathBuf>,
    },
}

pub fn run(command: &ProfileCommand) -> anyhow::Result<ExitCode> {
    match command {
        ProfileCommand::List => {
            for profile in HandProfile::builtin_names().filter_map(HandProfile::builtin) {
                out!(
                    "{:<10} {:<42} {:>2} joints",
                    profile.name,
                    profile.model,
                    profile.joints.len()
                )?;
            }
        }
        ProfileCommand::Urdf { hand, out } => {
            let profile = resolve(hand)?;
            let urdf = profile.to_urdf();
            match out {
                Some(path) => {
                    write(path, &urdf)?;
                    out!("wrote {} (URDF of `{}`)", path.display(), profile.name)?;
                }
                None => out!("{}", urdf.trim_end())?,
            }
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// The profile `hand` names: a builtin profile of that name, else the profile file at that path.
fn resolve(hand: &str) -> anyhow::Result<HandProfile> {
    if let Some(profile) = HandProfile::builtin(hand) {
        return Ok(profile);
    }
    let path = Path::new(hand);
    if !path.is_file() {
        anyhow::bail!(
            "`{hand}` is neither a builtin hand profile ({}) nor a profile file",
            HandProfile::builtin_names().collect::<Vec<_>>().join(", ")
        );
    }
    // The loader's errors name the file, the line and the field.
    Ok(HandProfile::load(path)?)
}

fn write(path: &Path, text: &str) -> anyhow::Result<()> {
    std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn urdf_to(hand: &str, out: &Path) -> anyhow::Result<ExitCode> {
        run(&ProfileCommand::Urdf {
            hand: hand.to_string(),
            out: Some(out.to_path_buf()),
        })
    }

    #[test]
    fn a_builtin_profile_is_written_as_urdf() {
        let dir = tempfile::tempdir().unwrap();
        for name in HandProfile::builtin_names() {
            let out = dir.path().join(format!("{name}.urdf"));
            urdf_to(name, &out).unwrap();
            let text = std::fs::read_to_string(&out).unwrap();
            assert!(text.starts_with("<?xml"), "{name}");
            assert!(
                text.contains(&format!(r#"<robot name="{name}">"#)),
                "{name}"
            );
            assert_eq!(text, HandProfile::builtin(name).unwrap().to_urdf());
        }
    }

    #[test]
    fn a_profile_file_is_read() {
        let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/hands/shadow.toml");
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("hand.urdf");
        urdf_to(file.to_str().unwrap(), &out).unwrap();
        let text = std::fs::read_to_string(&out).unwrap();
        assert!(text.contains(r#"<joint name="FFJ1" type="revolute">"#));
    }

    #[test]
    fn an_unknown_hand_is_refused_naming_it_and_the_builtins() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("x.urdf");
        let e = urdf_to("allegr0", &out).unwrap_err().to_string();
        assert!(e.contains("`allegr0`"), "{e}");
        for name in HandProfile::builtin_names() {
            assert!(e.contains(name), "{e}");
        }
        assert!(!out.exists());
    }

    #[test]
    fn a_bad_profile_file_is_refused_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("broken.toml");
        std::fs::write(&file, "[hand]\nname = 3\n").unwrap();
        let out = dir.path().join("x.urdf");
        let e = urdf_to(file.to_str().unwrap(), &out)
            .unwrap_err()
            .to_string();
        assert!(e.contains("broken.toml"), "{e}");
        assert!(!out.exists());
    }

    #[test]
    fn an_unwritable_output_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("no/such/dir/x.urdf");
        let e = format!("{:#}", urdf_to("revo2", &out).unwrap_err());
        assert!(e.contains("no/such/dir/x.urdf"), "{e}");
    }
}
