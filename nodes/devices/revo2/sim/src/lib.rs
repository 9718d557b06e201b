//! The emulated BrainCo Revo2, for running the pipeline without hardware.
//!
//! - [`hand`]: six joints with speed limits and dynamics, the five control modes, current that
//!   follows the load, objects in the hand that produce tactile force (pure);
//! - [`contact`]: objects that touch the fingertip pads by geometry, placed by the hand
//!   profile's kinematics (pure);
//! - [`device`]: the Revo2 firmware as an EtherCAT application: the object dictionary of
//!   `teleop-revo2-protocol`, PDO assignment, process data, configuration side effects;
//! - [`firmware`]: the firmware upgrade over FoE in BOOT (section 6): checks with the FoE error
//!   codes, simulated flash with its write time (BUSY), restart with the new version;
//! - [`revo2_subdevice`]: the two inside the generic emulated ESC of `teleop-ecat-sim`, with the
//!   Revo2's identity, CoE and FoE, and a bootstrap mailbox of its own ([`BOOTSTRAP_MAILBOX`]);
//! - [`control`]: its control socket's commands on the simulator kit (`teleop-sim-kit`).
//!
//! Must not depend on: the Revo2 node or ethercrab (a master bug must not hide behind shared
//! master code).

pub mod contact;
pub mod control;
pub mod device;
pub mod firmware;
pub mod hand;

use teleop_ecat_sim::{mailbox_protocols, EscConfig, Identity, SubDevice};

pub use device::{Revo2, Versions};
pub use firmware::{FlashTiming, Upgrade};

/// The bootstrap mailbox (receive, send: offset and size) of the emulated Revo2, used in BOOT:
/// larger than the standard 128-byte mailbox, and elsewhere, so that a master has to move its
/// sync managers before requesting BOOT, as on devices whose boot loader has its own mailbox.
pub const BOOTSTRAP_MAILBOX: ((u16, u16), (u16, u16)) = ((0x1000, 256), (0x1200, 256));

/// An emulated Revo2 with an optional joint-space object in its hand ([`hand::VirtualObject`]:
/// the model whose numbers the in-process tests pin; a geometric object goes in through
/// [`Revo2::hand_mut`]), acting on every AL control write at once (for callers that drive its
/// clock themselves).
pub fn revo2_subdevice(object: Option<hand::VirtualObject>, serial: u32) -> SubDevice<Revo2> {
    revo2_subdevice_with_loop(object, serial, std::time::Duration::ZERO)
}

/// An emulated Revo2 whose firmware reads AL control once per `firmware_loop` (see
/// [`EscConfig::firmware_loop`]), as the `teleop-sim-revo2` process runs it.
pub fn revo2_subdevice_with_loop(
    object: Option<hand::VirtualObject>,
    serial: u32,
    firmware_loop: std::time::Duration,
) -> SubDevice<Revo2> {
    let config = EscConfig {
        identity: Identity {
            vendor_id: teleop_revo2_protocol::VENDOR_ID,
            product_code: teleop_revo2_protocol::PRODUCT_CODE,
            revision: teleop_revo2_protocol::REVISION,
            serial,
        },
        name: teleop_revo2_protocol::DEVICE_NAME.to_string(),
        mailbox_protocols: mailbox_protocols::COE | mailbox_protocols::FOE,
        bootstrap_rx_mailbox: BOOTSTRAP_MAILBOX.0,
        bootstrap_tx_mailbox: BOOTSTRAP_MAILBOX.1,
        firmware_loop,
        ..EscConfig::default()
    };
    revo2_behind(config, object)
}

/// The emulated Revo2's firmware (with an optional joint-space object in its hand) behind an ESC
/// configured as `config`: the Revo2's own, or a test's variant of it (another identity, other
/// mailboxes).
pub fn revo2_behind(config: EscConfig, object: Option<hand::VirtualObject>) -> SubDevice<Revo2> {
    let hand = hand::Hand::new(
        hand::HandParams::default(),
        object.map(hand::ObjectModel::Joint),
    );
    SubDevice::new(config, Revo2::new(hand, &Versions::default()))
}
