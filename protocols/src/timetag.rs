//! Wall-clock time to OSC (NTP) timetags.

use rosc::OscTime;
use std::time::SystemTime;

/// The OSC timetag meaning "immediately" (NTP seconds 0, fraction 1).
pub const IMMEDIATE: OscTime = OscTime {
    seconds: 0,
    fractional: 1,
};

/// The NTP timetag of `t`; "immediately" for times rosc cannot represent (before 1970, after 2036)
/// rather than an error, since a late-but-shown frame beats a dropped one.
pub fn osc_time(t: SystemTime) -> OscTime {
    OscTime::try_from(t).unwrap_or(IMMEDIATE)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::{Duration, UNIX_EPOCH};

    #[test]
    fn converts_unix_time_to_ntp() {
        let t = UNIX_EPOCH + Duration::from_millis(1_700_000_000_500);
        let tag = osc_time(t);
        assert_eq!(tag.seconds, 1_700_000_000 + 2_208_988_800);
        assert_eq!(tag.fractional, 1 << 31);
        assert_eq!(osc_time(UNIX_EPOCH - Duration::from_secs(1)), IMMEDIATE);
    }
}
