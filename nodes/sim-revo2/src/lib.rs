//! The emulated BrainCo Revo2, for running the pipeline without hardware.
//!
//! - [`hand`]: six joints with speed limits and dynamics, the five control modes, current that
//!   follows the load, virtual objects that produce tactile force (pure);
//! - [`device`]: the Revo2 firmware as an EtherCAT application: the object dictionary of
//!   `teleop-revo2-protocol`, PDO assignment, process data, configuration side effects;
//! - [`revo2_subdevice`]: the two inside the generic emulated ESC of `teleop-ecat-sim`, with the
//!   Revo2's identity.
//!
//! Must not depend on: the Revo2 node or ethercrab (a master bug must not hide behind shared
//! master code).

pub mod device;
pub mod hand;

use teleop_ecat_sim::{EscConfig, Identity, SubDevice};

pub use device::{Revo2, Versions};

/// An emulated Revo2 with an optional virtual object in its hand.
pub fn revo2_subdevice(object: Option<hand::VirtualObject>, serial: u32) -> SubDevice<Revo2> {
    let config = EscConfig {
        identity: Identity {
            vendor_id: teleop_revo2_protocol::VENDOR_ID,
            product_code: teleop_revo2_protocol::PRODUCT_CODE,
            revision: teleop_revo2_protocol::REVISION,
            serial,
        },
        name: teleop_revo2_protocol::DEVICE_NAME.to_string(),
        ..EscConfig::default()
    };
    let hand = hand::Hand::new(hand::HandParams::default(), object);
    SubDevice::new(config, Revo2::new(hand, &Versions::default()))
}
