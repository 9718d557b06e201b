//! The virtual objects a simulated hand can hold, one name each on every simulator (the
//! `object` command, the `--object` argument). Each simulator gives an object its geometry: in
//! its own joint space, or (the Revo2's by default) as a shape touched by the fingertip pads;
//! one that has no such object says so.

/// An object in the simulated hand.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Object {
    /// A ball about a third of a fist, under the fingers.
    Ball,
    /// A bar across the fingers (across the palm, wrapped, where a simulator gives it that
    /// place).
    Bar,
}

impl Object {
    /// The object named `name` (`ball`, `bar`); `none` and any other name: no object.
    pub fn parse(name: &str) -> Option<Self> {
        match name {
            "ball" => Some(Self::Ball),
            "bar" => Some(Self::Bar),
            _ => None,
        }
    }

    /// Its name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Ball => "ball",
            Self::Bar => "bar",
        }
    }

    /// The `--object` argument's value (`ball`, `bar`, `none`), checked: `Err` names the
    /// accepted values.
    pub fn from_arg(text: &str) -> Result<Option<Self>, String> {
        match text {
            "none" => Ok(None),
            other => Self::parse(other)
                .map(Some)
                .ok_or_else(|| format!("unknown object {other:?}: use ball, bar or none")),
        }
    }
}

/// The `--object` argument of a simulated hand.
#[derive(Debug, Clone, clap::Args)]
pub struct ObjectArg {
    /// The virtual object in the hand at start: `ball` (under the fingers), `bar` (across the
    /// palm) or `none`; a simulator without that object refuses it.
    #[arg(long = "object", default_value = "ball")]
    pub name: String,
}

impl ObjectArg {
    /// The object named, checked.
    pub fn object(&self) -> anyhow::Result<Option<Object>> {
        Object::from_arg(&self.name).map_err(anyhow::Error::msg)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip() {
        for o in [Object::Ball, Object::Bar] {
            assert_eq!(Object::parse(o.name()), Some(o));
            assert_eq!(Object::from_arg(o.name()), Ok(Some(o)));
        }
        assert_eq!(Object::from_arg("none"), Ok(None));
        assert!(Object::from_arg("cube").is_err());
    }
}
