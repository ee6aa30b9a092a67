//! The FES stimulator CAN protocol (to be written).
