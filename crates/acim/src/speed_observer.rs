//! The f32 drive's speed observer, chosen by configuration
//! ([`crate::config::EstimationSettings::observer`]): the paper's reduced-order observer
//! (eq. 12, [`crate::observer`]) or the flux observer with speed adaptation
//! ([`crate::flux_observer`]; Hinkkanen, Harnefors and Luomi 2010).
//!
//! One drive type for both, so that the simulator, the virtual board and the firmware
//! build the same [`crate::Drive`] from the same settings and a setting, not a rebuild,
//! chooses the observer. Each method dispatches on the variant (a compare and a branch
//! per call in the step); what the drive does around each observer (the orientation
//! correction, the regeneration limit, the running Rs law's band, the frame lock) follows
//! the variant's own answers ([`SpeedObserver`]). The flux observer's design is built
//! here, outside the interrupt, from the drive's configuration.

use crate::config::{ConfigError, DriveConfig, ObserverChoice};
use crate::flux_observer::FluxObserver;
use crate::frames::SinCosValue;
use crate::observer::{
    ObserverCoeffs, ReducedOrderObserver, SpeedEstimate, SpeedObserver, SpeedObserverInputs,
};

/// The speed observer of the f32 drive: one of the two, with its state (and, for the
/// flux observer, its design).
#[derive(Clone, Debug)]
pub enum DriveObserver {
    /// The paper's reduced-order observer (its design is the drive's, eq. 12, 14).
    Reduced(ReducedOrderObserver),
    /// The flux observer with speed adaptation.
    Flux(FluxObserver),
}

impl DriveObserver {
    /// The observer `cfg.estimation.observer` names, designed for `cfg` (its machine
    /// model, control period, speed limit and flux current; design time). The
    /// configuration is validated by [`crate::DriveDesign::new`], which the drive's
    /// constructors run as well.
    pub fn new(cfg: &DriveConfig) -> Result<Self, ConfigError> {
        Ok(match cfg.estimation.observer {
            ObserverChoice::Reduced => DriveObserver::Reduced(ReducedOrderObserver::new()),
            ObserverChoice::Flux => DriveObserver::Flux(
                FluxObserver::new(
                    &cfg.machine,
                    cfg.loops.control_period,
                    cfg.limits.max_speed,
                    cfg.loops.flux_current,
                    cfg.limits.current_limit,
                )
                .map_err(|_| ConfigError::Invalid {
                    field: "estimation.observer",
                    rule: "a flux-observer design at this control period (each bandwidth times \
                           the period below 0.5)",
                })?,
            ),
        })
    }

    /// Which observer this is.
    pub fn choice(&self) -> ObserverChoice {
        match self {
            DriveObserver::Reduced(_) => ObserverChoice::Reduced,
            DriveObserver::Flux(_) => ObserverChoice::Flux,
        }
    }
}

impl SpeedObserver for DriveObserver {
    #[inline(always)]
    fn far_side_term(&self) -> bool {
        match self {
            DriveObserver::Reduced(o) => o.far_side_term(),
            DriveObserver::Flux(o) => o.far_side_term(),
        }
    }
    #[inline(always)]
    fn orientation_correction(&self) -> bool {
        match self {
            DriveObserver::Reduced(o) => o.orientation_correction(),
            DriveObserver::Flux(o) => o.orientation_correction(),
        }
    }
    #[inline(always)]
    fn regeneration_limit(&self) -> bool {
        match self {
            DriveObserver::Reduced(o) => o.regeneration_limit(),
            DriveObserver::Flux(o) => o.regeneration_limit(),
        }
    }
    #[inline(always)]
    fn rs_running_at_speed(&self) -> bool {
        match self {
            DriveObserver::Reduced(o) => o.rs_running_at_speed(),
            DriveObserver::Flux(o) => o.rs_running_at_speed(),
        }
    }
    #[inline(always)]
    fn frame_lock(&self) -> bool {
        match self {
            DriveObserver::Reduced(o) => o.frame_lock(),
            DriveObserver::Flux(o) => o.frame_lock(),
        }
    }
    #[inline(always)]
    fn frame_pull(&self, model: &SinCosValue<f32>) -> f32 {
        match self {
            DriveObserver::Reduced(o) => o.frame_pull(model),
            DriveObserver::Flux(o) => o.frame_pull(model),
        }
    }
    #[inline(always)]
    fn update(&mut self, coeffs: &ObserverCoeffs<f32>, x: &SpeedObserverInputs) -> SpeedEstimate {
        match self {
            DriveObserver::Reduced(o) => SpeedObserver::update(o, coeffs, x),
            DriveObserver::Flux(o) => SpeedObserver::update(o, coeffs, x),
        }
    }
    fn reset(&mut self) {
        match self {
            DriveObserver::Reduced(o) => SpeedObserver::reset(o),
            DriveObserver::Flux(o) => SpeedObserver::reset(o),
        }
    }
    #[inline(always)]
    fn start_running(&mut self, i_sq: f32) {
        match self {
            DriveObserver::Reduced(o) => SpeedObserver::start_running(o, i_sq),
            DriveObserver::Flux(o) => SpeedObserver::start_running(o, i_sq),
        }
    }
    #[inline(always)]
    fn preset_speed(&mut self, speed: f32) {
        match self {
            DriveObserver::Reduced(o) => SpeedObserver::preset_speed(o, speed),
            DriveObserver::Flux(o) => SpeedObserver::preset_speed(o, speed),
        }
    }
    #[inline(always)]
    fn estimate(&self) -> SpeedEstimate {
        match self {
            DriveObserver::Reduced(o) => SpeedObserver::estimate(o),
            DriveObserver::Flux(o) => SpeedObserver::estimate(o),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::DriveConfig;

    #[test]
    fn the_setting_chooses_the_observer() {
        let mut cfg = DriveConfig::paper_defaults();
        let o = DriveObserver::new(&cfg).unwrap();
        assert_eq!(o.choice(), ObserverChoice::Reduced);
        assert!(o.orientation_correction() && o.regeneration_limit() && !o.frame_lock());
        cfg.estimation.observer = ObserverChoice::Flux;
        let o = DriveObserver::new(&cfg).unwrap();
        assert_eq!(o.choice(), ObserverChoice::Flux);
        assert!(!o.orientation_correction() && !o.regeneration_limit() && o.frame_lock());
        // a period too long for the flux observer's bandwidths: a named error
        cfg.loops.control_period = 2e-3;
        assert_eq!(
            DriveObserver::new(&cfg).unwrap_err().field(),
            "estimation.observer"
        );
    }
}
