//! What the OSC output did with every frame and event: sent, refused or altered.

/// A snapshot of [`crate::OscOutput`]'s counters, all running totals since it was made.
///
/// Every datagram handed to the output ends up in `packets_sent` or `send_errors`; every value
/// changed or left out on the way is in one of the other counters.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct OutputCounters {
    /// UDP datagrams handed to the operating system.
    pub packets_sent: u64,
    /// Bytes in those datagrams (OSC payload only).
    pub bytes_sent: u64,
    /// Datagrams the operating system refused (buffer full, unreachable, refused, too big); lost.
    pub send_errors: u64,
    /// Of `send_errors`, those over the largest UDP payload (65 507 bytes): a frame with far too
    /// many bones for one bundle.
    pub oversized_packets: u64,
    /// Values replaced because they were not finite (a scalar by 0, a position by zero, a
    /// rotation by the identity), summed over the native, VMC and VRChat encoders.
    pub non_finite_replaced: u64,
    /// Event integers beyond int32 sent as `i32::MAX` (beat index, beats per bar).
    pub clamped_values: u64,
    /// VRChat trackers skipped because their bone was not in the frame.
    pub vrchat_missing_bones: u64,
}
