//! `coil-thermal limits` and `alarm-limit`: dispatch in place, the maths
//! arrives with `src/protect` (stage 2).

use anyhow::{bail, Result};

use super::common::{self, NOT_YET};
use super::{AlarmLimitArgs, LimitsArgs};

/// Runs `limits`.
pub fn limits(a: LimitsArgs) -> Result<()> {
    // Validate the model first, so a bad model is reported as such.
    common::model_file(&a.model)?;
    let _ = (a.current_a, a.horizon_s, a.ambient_c, a.json);
    bail!(
        "`limits` (time to limit, maximum safe current, runaway current) is {NOT_YET} in this build: it arrives with the protection module `src/protect` (stage 2)"
    )
}

/// Runs `alarm-limit`.
pub fn alarm_limit(a: AlarmLimitArgs) -> Result<()> {
    if !(a.critical_c.is_finite() && a.ambient_c.is_finite()) {
        bail!("--critical-c and --ambient-c must be finite");
    }
    let _ = (a.factors, a.json);
    bail!(
        "`alarm-limit` (the derating rule) is {NOT_YET} in this build: it arrives with the protection module `src/protect` (stage 2)"
    )
}
