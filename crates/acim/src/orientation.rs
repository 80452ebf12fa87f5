//! Orientation correction (beyond the paper): a stator-frequency correction from the
//! d-axis residual that stabilises field orientation in regeneration.
//!
//! The paper's orientation mode s^2 + s/tau_r + w_s w_slip = 0 (x = lambda_d - lambda_hat,
//! y = lambda_q) is neutral at zero torque and unstable in regeneration. The steady d-axis
//! residual r_d = (Rs - Rs_hat) i_sd - w_s y, which the eq. (20) current model already
//! integrates (its error e_d is r_d/Rs_hat), drives a stator-frequency correction
//! dw = -k sign(w_s) r_d / lambda_ref. The mode becomes
//! s^2 + s(1/tau_r + k|w_s|) + k|w_s|/tau_r + w_s w_slip = 0, stable in regeneration for
//! k > tau_r |w_slip|. It fades in between `orientation_fade` (no information at w_s = 0),
//! and Rs adapts only below `rs_max_frequency`, where the orientation part of r_d
//! vanishes. `orientation_gain = 0` is the paper's scheme. Derivation, the measured
//! stability map and before/after figures: `docs/orientation-stability.md`.

use crate::num::Num;
use crate::num::PerUnitBases;
use crate::num::Units;

/// The orientation correction's constants ([`crate::orientation`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OrientationDesign<N: Num = f32> {
    /// k / lambda_ref, 1/Wb.
    pub gain_per_flux: N::Gain,
    /// c in the load scheduling k(i_sq) = k max(1, c |i_sq|), 1/A:
    /// [`ORIENTATION_GAIN_MARGIN`](crate::design::ORIENTATION_GAIN_MARGIN) / (k i_sd*).
    pub load_factor_per_current: N::Gain,
    /// |w_s| where the fade-in starts, rad/s electrical.
    pub fade_start: N,
    /// 1 / (fade upper - fade lower), s/rad.
    pub inv_fade_width: N::Gain,
    /// Largest |correction|, rad/s electrical.
    pub limit: N,
    /// The far-side gain c (dimensionless).
    pub far_side_gain: N::Gain,
    /// a in its load scheduling c(i_sq) = c max(1, a |i_sq|), 1/A:
    /// [`FAR_SIDE_LOAD_FRACTION`](crate::design::FAR_SIDE_LOAD_FRACTION) / i_sd*.
    pub far_side_load_factor: N::Gain,
}

/// The fade in |w_s|: 0 below `orientation_fade`'s start (no orientation information at
/// w_s = 0), 1 above its end, linear between, from the stator frequency
/// `stator_frequency` (rad/s electrical). Shared by the correction and the far-side term
/// of the observer (`DriveConfig.estimation.far_side_gain`), so both fade in together.
#[inline(always)]
pub fn fade<N: Num>(d: &OrientationDesign<N>, stator_frequency: N) -> N {
    // (complete above the band, where the drive runs most)
    N::gain(d.inv_fade_width, stator_frequency.abs() - d.fade_start)
        .clamp_at_limits(N::ZERO, N::ONE)
}

/// The correction dw (rad/s electrical) added to p Omega_hat before the slip law, from
/// the stator frequency of the last step `stator_frequency` (rad/s electrical), the Rs
/// estimate `rs_estimate` (ohm) and the d-axis current-model error `current_error` (A,
/// eq. 20): in field orientation the steady residual is r_d = Rs_hat e_d = -w_s lambda_q,
/// so dw = -k sign(w_s) r_d / lambda_ref turns the frame toward the flux. Under load
/// the gain becomes k max(1, c |i_sq|) with `torque_current` = i_sq (A), so that it stays
/// above the stability bound tau_r |w_slip| = |i_sq| / i_sd*. Faded in over
/// `fade`, bounded by `limit`. The caller applies it only with a settled flux and not
/// while magnetizing.
#[inline(always)]
pub fn correction<N: Num>(
    d: &OrientationDesign<N>,
    stator_frequency: N,
    rs_estimate: N,
    current_error: N,
    torque_current: N,
) -> N {
    let w = fade(d, stator_frequency);
    let r_d = rs_estimate * current_error;
    let signed = if stator_frequency >= N::ZERO {
        -r_d
    } else {
        r_d
    };
    // load scheduling: k(i_sq) = k max(1, c |i_sq|) keeps k above tau_r |w_slip|
    let load = N::gain(d.load_factor_per_current, torque_current.abs());
    let scale = if load > N::ONE { load } else { N::ONE };
    (N::gain_mul(d.gain_per_flux, w, signed) * scale).clamp(-d.limit, d.limit)
}

impl OrientationDesign<f32> {
    /// This design in the arithmetic `N` with the bases `b`, for the fade band `fade`
    /// (rad/s electrical, its start and end); fails naming the setting the value depends
    /// on.
    pub fn convert<N: Num + Units>(
        &self,
        b: &PerUnitBases,
        fade: (f32, f32),
    ) -> Result<OrientationDesign<N>, &'static str> {
        let g = crate::num::gain_in::<N>;
        let pu =
            |x: f32, base: f32, field: &'static str| N::checked_from_f32(x / base).ok_or(field);
        Ok(OrientationDesign {
            gain_per_flux: g(
                self.gain_per_flux * b.voltage / b.frequency,
                "estimation.orientation_gain",
            )?,
            load_factor_per_current: g(
                self.load_factor_per_current * b.current,
                "estimation.orientation_gain",
            )?,
            fade_start: pu(self.fade_start, b.frequency, "estimation.orientation_fade")?,
            inv_fade_width: g(
                b.frequency / (fade.1 - fade.0),
                "estimation.orientation_fade",
            )?,
            limit: pu(self.limit, b.frequency, "limits.max_speed")?,
            far_side_gain: g(self.far_side_gain, "estimation.far_side_gain")?,
            far_side_load_factor: g(
                self.far_side_load_factor * b.current,
                "estimation.far_side_gain",
            )?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::{DriveConfig, DriveDesign};

    fn design() -> OrientationDesign<f32> {
        DriveDesign::new(DriveConfig::paper_defaults())
            .unwrap()
            .orientation
    }

    #[test]
    fn silent_below_the_fade_and_full_above() {
        let d = design();
        // below the fade-in: nothing, whatever the residual
        assert_eq!(correction(&d, 0.5 * d.fade_start, 10.0, 0.1, 0.0), 0.0);
        // above it: -k r_d / lambda_ref for w_s > 0, sign flipped for w_s < 0
        let above = d.fade_start + 2.0 / d.inv_fade_width;
        let c = correction(&d, above, 10.0, 0.01, 0.0);
        assert!((c - (-d.gain_per_flux * 0.1)).abs() < 1e-5, "{c}");
        assert_eq!(correction(&d, -above, 10.0, 0.01, 0.0), -c);
    }

    #[test]
    fn bounded_and_nan_safe() {
        let d = design();
        let above = d.fade_start + 2.0 / d.inv_fade_width;
        assert_eq!(correction(&d, above, 10.0, -1e9, 0.0), d.limit);
        assert_eq!(correction(&d, above, 10.0, 1e9, 0.0), -d.limit);
        let n = correction(&d, above, f32::NAN, 1.0, f32::NAN);
        assert!(n.abs() <= d.limit);
    }
}
