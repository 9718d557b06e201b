//! AL state machine rules (ETG.1000.6 6.4.1): which requested transitions exist and what the
//! SubDevice must check before taking them.

use crate::{al_status, AlState};

/// What has to be verified before an upward transition.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Check {
    /// INIT -> PRE-OP: SM0/SM1 against the standard mailbox (else 0x0016).
    StandardMailbox,
    /// INIT -> BOOT: SM0/SM1 against the bootstrap mailbox (else 0x0015).
    BootstrapMailbox,
    /// PRE-OP -> SAFE-OP: SM2/SM3 against the process image (else 0x001D / 0x001E).
    ProcessData,
    /// SAFE-OP -> OP: nothing beyond the application's consent.
    Nothing,
}

/// Kind of a requested transition between two different states.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Step {
    /// Upward: checked, and the application may refuse.
    Up(Check),
    /// Downward: always taken.
    Down,
}

/// Classifies `from -> to` (`from != to`); `Err` with the AL status code of an invalid request.
pub(crate) fn classify(from: AlState, to: AlState) -> Result<Step, u16> {
    use AlState::*;
    match (from, to) {
        (Init, PreOp) => Ok(Step::Up(Check::StandardMailbox)),
        (Init, Boot) => Ok(Step::Up(Check::BootstrapMailbox)),
        (PreOp, SafeOp) => Ok(Step::Up(Check::ProcessData)),
        (SafeOp, Op) => Ok(Step::Up(Check::Nothing)),
        (PreOp | SafeOp | Op | Boot, Init) => Ok(Step::Down),
        (SafeOp | Op, PreOp) | (Op, SafeOp) => Ok(Step::Down),
        _ => Err(al_status::INVALID_STATE_CHANGE),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use AlState::*;

    #[test]
    fn transitions() {
        assert_eq!(classify(Init, PreOp), Ok(Step::Up(Check::StandardMailbox)));
        assert_eq!(classify(Init, SafeOp), Err(0x0011));
        assert_eq!(classify(Init, Op), Err(0x0011));
        assert_eq!(classify(PreOp, Op), Err(0x0011));
        assert_eq!(classify(PreOp, Boot), Err(0x0011));
        assert_eq!(classify(Boot, PreOp), Err(0x0011));
        assert_eq!(classify(Boot, Init), Ok(Step::Down));
        assert_eq!(classify(Op, PreOp), Ok(Step::Down));
        assert_eq!(classify(SafeOp, Op), Ok(Step::Up(Check::Nothing)));
    }
}
