//! The speed controller's design: i_sq* from the speed error and, optionally, from
//! feed-forwards, designed from the inertia J, the torque constant k_t = 1.5 p lambda_ref
//! and one bandwidth alpha (rad/s), the same in rad/s at every control rate.
//!
//! The mechanical plant (eq. 9b with Te = k_t i_sq) is J dOmega/dt = k_t i_sq - B Omega -
//! T_L. Two designs:
//!
//! - **PI on the estimated speed** (the paper's Fig. 1; without the feed-forward):
//!   kp = 2 alpha J / k_t, ki = alpha^2 J / k_t. The loop's characteristic polynomial is
//!   J (s + alpha)^2, a double pole at alpha; the loop is of type 2, so a ramp is followed
//!   without a steady lag, and a load step T slows the rotor by at most T / (e J alpha)
//!   (the peak of T t e^(-alpha t) / J). (The paper defaults' 12.5 rad/s are the gains of
//!   the project's earlier design, kp = 25 J / k_t with its PI zero at 6.25 rad/s.)
//! - **Two degrees of freedom with the observer's load estimate** (`feedforward`): the
//!   torque current is the reference feed-forward (the ramp's slope times J / k_t and the
//!   friction at the reference, B Omega* / k_t), the load feed-forward T_L_hat / k_t
//!   (eq. 12's load-torque estimate, the paper's reason for estimating T_L) and the
//!   proportional feedback kp = 2 alpha J / k_t, with no integral: in steady state the
//!   observer's current error is zero, so T_L_hat = k_t i_sq - B Omega_hat and the
//!   feed-forward alone holds the load; the observer's load state is the loop's integral
//!   action. A second integrator beside it charges while the estimate catches up with a
//!   load step and then overshoots: on motulator's 2.2 kW machine at 750 rpm, a
//!   rated-load step gave 41 rpm over and 0.25 s back within 1 % with ki = alpha^2 J /
//!   k_t, 3 rpm and 0.10 s without. With a correct model the observer's error dynamics
//!   (eq. 14) do not depend on the current it is fed (separation); an inertia error makes
//!   T_L_hat carry (J - J_hat) dOmega/dt, which turns the plant the feedback sees into
//!   J_hat, the inertia it is designed for. A resistance error is different: it biases
//!   the speed estimate by -dR i_sq / (p lambda_r), a path from the current back to the
//!   feedback, and on the paper's machine (R_s 10.5 ohm) +50 % R_s without the
//!   estimator lost control with the feed-forward where the PI holds it: the
//!   feed-forward is for a drive that estimates R_s (the nameplate path's default).
//!
//! The design is f32 SI; the fixed-point drive rescales it (`fixed::convert`).

use crate::num::Num;
use crate::params::MachineParams;
use crate::pi::PiConfig;

/// The speed controller's coefficients (configuration, apart from state).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SpeedLoopConfig<N: Num = f32> {
    /// The disturbance PI on the speed error (A per rad/s, and per rad/s per step), with
    /// the q-current limit (A).
    pub pi: PiConfig<N>,
    /// J / (k_t Ts): the ramp's speed change per step (rad/s) -> torque current (A);
    /// zero without the feed-forward (as the two below).
    pub acceleration_feedforward: N::Gain,
    /// B / k_t: the speed reference (rad/s) -> the torque current of the friction (A).
    pub friction_feedforward: N::Gain,
    /// 1 / k_t: the load-torque estimate (N m) -> torque current (A).
    pub load_feedforward: N::Gain,
    /// Whether the feed-forwards are on (the three gains above are zero otherwise, and
    /// the step skips them).
    pub feedforward: bool,
}

impl SpeedLoopConfig<f32> {
    /// The design for `bandwidth` (rad/s) at rotor flux `rotor_flux` (Wb), period `ts`
    /// (s), q-current limit `current_limit` (A): the PI with its double pole at the
    /// bandwidth, or (`feedforward`) the two-degree-of-freedom loop (module docs).
    pub fn new(
        m: &MachineParams,
        rotor_flux: f32,
        bandwidth: f32,
        ts: f32,
        current_limit: f32,
        feedforward: bool,
    ) -> Self {
        // k_t > 0 for any valid design (the flux reference is positive); the floor only
        // keeps a degenerate input finite
        let kt = m.torque_constant(rotor_flux).max(1e-6);
        let j_over_kt = m.inertia() / kt;
        // kp = 2 alpha J / k_t and ki = alpha^2 J / k_t = kp (2 alpha) / 4, written in the
        // earlier design's order of operations (J w / k_t, kp w / 4 with w = 2 alpha) so
        // that its gains come out bit for bit at the paper defaults
        let w = 2.0 * bandwidth;
        let kp = m.inertia() * w / kt;
        if feedforward {
            Self {
                // the observer's load state is the integral action
                pi: PiConfig::new(kp, 0.0, ts, current_limit),
                acceleration_feedforward: j_over_kt / ts,
                friction_feedforward: m.viscous_friction() / kt,
                load_feedforward: 1.0 / kt,
                feedforward: true,
            }
        } else {
            Self {
                pi: PiConfig::new(kp, kp * w * 0.25, ts, current_limit),
                acceleration_feedforward: 0.0,
                friction_feedforward: 0.0,
                load_feedforward: 0.0,
                feedforward: false,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The paper defaults' 12.5 rad/s give the earlier design's gains exactly.
    #[test]
    fn the_paper_defaults_keep_their_gains() {
        let m = MachineParams::paper_table1();
        let flux = m.rotor_flux_for(1.5);
        let kt = m.torque_constant(flux);
        let c = SpeedLoopConfig::new(&m, flux, 12.5, 200e-6, 4.4, false);
        let kp = m.inertia() * 25.0 / kt;
        assert_eq!(c.pi.kp, kp);
        assert_eq!(c.pi.ki_ts, kp * 25.0 * 0.25 * 200e-6);
    }

    /// Without the load feed-forward, kp and ki place both closed-loop poles of
    /// J s^2 + k_t (kp s + ki) at -alpha; with it the proportional gain is the same and
    /// the observer's load state integrates.
    #[test]
    fn the_loop_has_a_double_pole_at_the_bandwidth() {
        let m = MachineParams::paper_table1();
        let flux = m.rotor_flux_for(1.5);
        let kt = m.torque_constant(flux);
        let (alpha, ts) = (40.0, 200e-6);
        let c = SpeedLoopConfig::new(&m, flux, alpha, ts, 4.4, false);
        // s^2 + (k_t kp / J) s + k_t ki / J = (s + alpha)^2
        let a1 = kt * c.pi.kp / m.inertia();
        let a0 = kt * (c.pi.ki_ts / ts) / m.inertia();
        assert!((a1 - 2.0 * alpha).abs() < 1e-3 * alpha, "{a1}");
        assert!((a0 - alpha * alpha).abs() < 1e-3 * alpha * alpha, "{a0}");
        assert_eq!(c.load_feedforward, 0.0);
        assert_eq!(c.acceleration_feedforward, 0.0);
        assert_eq!(c.friction_feedforward, 0.0);
        let ff = SpeedLoopConfig::new(&m, flux, alpha, ts, 4.4, true);
        assert!((ff.load_feedforward * kt - 1.0).abs() < 1e-6);
        // the ramp's step dv over Ts times J / k_t; the friction B / k_t
        assert!((ff.acceleration_feedforward * ts * kt / m.inertia() - 1.0).abs() < 1e-5);
        assert!((ff.friction_feedforward * kt / m.viscous_friction() - 1.0).abs() < 1e-5);
        assert_eq!(ff.pi.kp, c.pi.kp);
        assert_eq!(ff.pi.ki_ts, 0.0);
    }
}
