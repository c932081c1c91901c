//! What to change in a model file when the library's
//! `NetworkObserverBuilder` refuses it: one text for every caller (the
//! codegen generator, the host's library observer).
//!
//! `codegen` also compiles this file into its generator program, which
//! depends on the `coil-thermal` library alone: keep it to `coil_thermal`
//! and `core`.

use coil_thermal::BuildError;

/// The fix to suggest for `error`, a refusal of the network observer's
/// builder for a model file's `[observer]` settings, or `None` when the
/// error's own text says it all. `bias_noise_w2_per_s` is the growth of
/// each heat-input bias variance \[W^2/s\] the observer was built with (its
/// bias states are estimated when it is above 0).
pub fn observer_build_hint(error: &BuildError, bias_noise_w2_per_s: f64) -> Option<&'static str> {
    match error {
        BuildError::NotConverged {
            name: "steady_state_gain",
        } if bias_noise_w2_per_s > 0.0 => Some(
            "the sensors cannot see every source's heat-input bias (one thermocouple sees one \
             heat): name the sources whose heat they can see in `[observer] bias_sources` (for \
             a winding split into several nodes, the one with most of the heat), or freeze \
             the biases with `[observer] bias_noise_w2_per_s = 0`",
        ),
        BuildError::Unobservable { .. } => Some(
            "no thermocouple sees that node well enough to protect it: name a sensor on it or \
             next to it in `[observer] sensors` (or --sensor NODE)",
        ),
        _ => None,
    }
}
