//! The virtual stimulator on the CAN bus (to be written).
