//! The simulated Allegro Hand: its CAN firmware per protocol generation, 16-joint dynamics, a virtual object, a simulated slcan adapter.

pub mod adapter;
pub mod hand;
