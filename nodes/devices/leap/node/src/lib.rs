//! The LEAP Hand node: 16 Dynamixel XC330 servos polled on one serial bus.
