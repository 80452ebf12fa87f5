//! Load torque on the shaft (the `T_L(Omega)` of the paper's mechanical equation (2)).
//!
//! Sign convention: a load torque is positive when it opposes positive (forward) rotation,
//! so the mechanics read J dOmega/dt = Te - B Omega - T_L(Omega).

use acim::math::{clamp, is_finite};

/// Half-width of the linear zone of [`LoadTorque::Passive`], rad/s (mechanical).
///
/// Inside |Omega| < this band a passive brake acts as a stiff viscous damper
/// (slope `torque / PASSIVE_SPEED_BAND` N m s/rad) instead of a discontinuous Coulomb
/// torque, so the integrator does not chatter around zero speed and the brake can never
/// drive the rotor backwards (T_L Omega >= 0 always). A stalled rotor whose motor torque is
/// smaller than the brake torque therefore creeps at |Omega| < 0.5 rad/s (< 5 rpm) instead
/// of standing exactly still.
pub const PASSIVE_SPEED_BAND: f32 = 0.5;

/// Load torque model, `Copy` and closure-free so that a simulator can switch loads in time
/// and a no_std target can store it anywhere.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LoadTorque {
    /// No load torque (only the machine's own viscous friction B acts).
    #[default]
    None,
    /// Passive load opposing motion, like the paper's powder brake:
    /// T_L = torque * sign(Omega), with `torque` >= 0 in N m (a negative value is taken as
    /// its magnitude) and a linear zone |Omega| < [`PASSIVE_SPEED_BAND`].
    Passive {
        /// Braking torque magnitude, N m.
        torque: f32,
    },
    /// Active load of constant sign (a hanging weight): T_L = torque whatever the speed,
    /// N m. A positive value brakes forward rotation and, when larger than the motor torque,
    /// drives the machine backwards; a negative value drives it forwards (regeneration when
    /// the drive holds the speed).
    Active {
        /// Load torque, N m (positive opposes forward rotation).
        torque: f32,
    },
    /// Viscous load (e.g. an eddy-current brake or a linearised fan):
    /// T_L = coefficient * Omega, N m s/rad (coefficient >= 0, magnitude taken).
    Viscous {
        /// Viscous coefficient, N m s/rad.
        coefficient: f32,
    },
}

impl LoadTorque {
    /// Load torque T_L (N m, positive opposes forward rotation) at mechanical speed
    /// `omega` (rad/s). Non-finite parameters or speed give 0.
    pub fn torque(&self, omega: f32) -> f32 {
        let t = match *self {
            LoadTorque::None => 0.0,
            LoadTorque::Passive { torque } => {
                if is_finite(omega) {
                    torque.abs() * clamp(omega * (1.0 / PASSIVE_SPEED_BAND), -1.0, 1.0)
                } else {
                    0.0
                }
            }
            LoadTorque::Active { torque } => torque,
            LoadTorque::Viscous { coefficient } => coefficient.abs() * omega,
        };
        if is_finite(t) {
            t
        } else {
            0.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn passive_opposes_motion_and_is_linear_near_zero() {
        let l = LoadTorque::Passive { torque: 2.0 };
        assert_eq!(l.torque(10.0), 2.0);
        assert_eq!(l.torque(-10.0), -2.0);
        assert_eq!(l.torque(0.0), 0.0);
        assert!((l.torque(0.25) - 1.0).abs() < 1e-6);
        assert_eq!(LoadTorque::Passive { torque: -2.0 }.torque(10.0), 2.0);
        for w in [-3.0f32, -0.3, -0.01, 0.01, 0.3, 3.0] {
            assert!(l.torque(w) * w >= 0.0);
        }
    }

    #[test]
    fn active_and_others() {
        assert_eq!(LoadTorque::Active { torque: -1.5 }.torque(100.0), -1.5);
        assert_eq!(LoadTorque::Active { torque: 1.5 }.torque(-100.0), 1.5);
        assert_eq!(LoadTorque::None.torque(5.0), 0.0);
        assert_eq!(LoadTorque::Viscous { coefficient: 0.1 }.torque(-5.0), -0.5);
        assert_eq!(LoadTorque::Active { torque: f32::NAN }.torque(1.0), 0.0);
        assert_eq!(LoadTorque::Passive { torque: 1.0 }.torque(f32::NAN), 0.0);
    }
}
