//! The `candump -L` log line of a frame (can-utils' `lib.c`, `sprint_canframe`), the
//! format `cantools decode`, python-can's `CanutilsLogReader`, `canplayer` and
//! `log2asc` read:
//!
//! ```text
//! (1700000000.123456) can0 110#0102030405060708
//! ```
//!
//! Standard identifiers print as 3 hex digits, extended ones (`CAN_EFF_FLAG`) as 8, error
//! frames (`CAN_ERR_FLAG`) as 8 digits of the flag and the error class; a remote frame's
//! data is `R`. Hex digits are upper case, the time is seconds with 6 decimals.

use core::fmt::Write as _;

/// Extended frame format flag of a Linux `can_id`.
pub const CAN_EFF_FLAG: u32 = 0x8000_0000;
/// Remote transmission request flag.
pub const CAN_RTR_FLAG: u32 = 0x4000_0000;
/// Error frame flag.
pub const CAN_ERR_FLAG: u32 = 0x2000_0000;
const CAN_SFF_MASK: u32 = 0x0000_07FF;
const CAN_EFF_MASK: u32 = 0x1FFF_FFFF;

/// Appends the `candump -L` line (without the newline) of the frame with Linux `can_id`
/// `can_id` (flags included) and payload `data` (at most 8 bytes are written), received
/// at `t_realtime_ns` (CLOCK_REALTIME, ns) on `iface`.
pub fn log_line(out: &mut String, t_realtime_ns: u64, iface: &str, can_id: u32, data: &[u8]) {
    let _ = write!(
        out,
        "({}.{:06}) {iface} ",
        t_realtime_ns / 1_000_000_000,
        t_realtime_ns % 1_000_000_000 / 1_000
    );
    let _ = if can_id & CAN_ERR_FLAG != 0 {
        write!(out, "{:08X}#", can_id & (CAN_ERR_FLAG | CAN_EFF_MASK))
    } else if can_id & CAN_EFF_FLAG != 0 {
        write!(out, "{:08X}#", can_id & CAN_EFF_MASK)
    } else {
        write!(out, "{:03X}#", can_id & CAN_SFF_MASK)
    };
    if can_id & CAN_RTR_FLAG != 0 && can_id & CAN_ERR_FLAG == 0 {
        out.push('R');
        return;
    }
    for b in data.iter().take(8) {
        let _ = write!(out, "{b:02X}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The lines can-utils prints for each kind of frame.
    #[test]
    fn lines_are_can_utils_own() {
        let line = |t, id, data: &[u8]| {
            let mut s = String::new();
            log_line(&mut s, t, "can0", id, data);
            s
        };
        assert_eq!(
            line(1_700_000_000_123_456_789, 0x110, &[1, 2, 0xAB]),
            "(1700000000.123456) can0 110#0102AB"
        );
        assert_eq!(line(5_000_001_000, 0x000, &[]), "(5.000001) can0 000#");
        assert_eq!(
            line(0, CAN_EFF_FLAG | 0x1234_5678, &[0xFF]),
            "(0.000000) can0 12345678#FF"
        );
        assert_eq!(line(0, CAN_RTR_FLAG | 0x7FF, &[]), "(0.000000) can0 7FF#R");
        assert_eq!(
            line(0, CAN_ERR_FLAG | 0x40, &[0, 0, 0, 0, 0, 0, 0, 0]),
            "(0.000000) can0 20000040#0000000000000000"
        );
        assert_eq!(
            line(0, 0x123, &[0; 12]).len(),
            "(0.000000) can0 123#".len() + 16
        );
    }
}
