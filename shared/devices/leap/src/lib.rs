//! Dynamixel Protocol 2.0 and the XC330 servos of the LEAP Hand: pure, total codecs.
