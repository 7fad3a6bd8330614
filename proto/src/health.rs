//! The calibration health state of a frame ([`crate::FrameHeader::calib_health`]; issue 32,
//! docs/calibration-health.md).

/// How much the calibration that aligned a frame can be trusted, as the online estimator sees
/// it. The header carries [`code`](Self::code); 0 is "unknown", which is also what a
/// publisher older than the field sends.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[repr(u8)]
pub enum CalibrationHealth {
    /// Not assessed: a static calibration, no estimate yet, or a publisher that does not fill
    /// the field.
    #[default]
    Unknown = 0,
    /// The evidence agrees with the calibration to within the good threshold (1 px of flow by
    /// default) in every direction it was checked, and every direction is known that well.
    Good = 1,
    /// Usable, but the evidence proposes a correction of 1–3 px, some direction is not known
    /// to 1 px, or the alignment residual has grown; the estimator is still working on it.
    CanImprove = 2,
    /// The evidence says the calibration is off by 3 px or more (a dropped phone, a re-seated
    /// module) and the estimator has not (yet) taken the correction.
    NeedsRecalibration = 3,
}

impl CalibrationHealth {
    /// Every state, by code.
    pub const ALL: [CalibrationHealth; 4] = [
        CalibrationHealth::Unknown,
        CalibrationHealth::Good,
        CalibrationHealth::CanImprove,
        CalibrationHealth::NeedsRecalibration,
    ];

    /// The header's byte.
    pub fn code(self) -> u8 {
        self as u8
    }

    /// The state of a header byte; codes this build does not know read as `Unknown`.
    pub fn from_code(code: u8) -> CalibrationHealth {
        Self::ALL
            .get(usize::from(code))
            .copied()
            .unwrap_or(CalibrationHealth::Unknown)
    }

    /// `"unknown"`, `"good"`, `"can improve"`, `"needs recalibration"`.
    pub fn name(self) -> &'static str {
        match self {
            CalibrationHealth::Unknown => "unknown",
            CalibrationHealth::Good => "good",
            CalibrationHealth::CanImprove => "can improve",
            CalibrationHealth::NeedsRecalibration => "needs recalibration",
        }
    }
}

impl std::fmt::Display for CalibrationHealth {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip_and_unknown_codes_are_unknown() {
        for h in CalibrationHealth::ALL {
            assert_eq!(CalibrationHealth::from_code(h.code()), h);
        }
        assert_eq!(CalibrationHealth::from_code(0), CalibrationHealth::Unknown);
        assert_eq!(
            CalibrationHealth::from_code(200),
            CalibrationHealth::Unknown
        );
        assert_eq!(CalibrationHealth::Good.code(), 1);
        assert_eq!(
            CalibrationHealth::NeedsRecalibration.to_string(),
            "needs recalibration"
        );
    }
}
