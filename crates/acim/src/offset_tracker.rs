//! Running current-sensor offset tracker: the drift of the current
//! channels' offsets after the start's switches-off measurement, estimated from the DC
//! part of the stator voltage while the motor turns.
//!
//! ## Why the voltage's DC part is the offset
//!
//! A sensor offset `o` (stationary frame, A) that the drive does not subtract makes the
//! current loops regulate the measured current `i + o` to the references. Those are
//! constant in the rotating frame, so at any stator frequency `w_s != 0` the measured
//! current has no DC part in the stationary frame and the true one has `-o`. The stator
//! voltage equation in the stationary frame, `v = Rs i + d psi_s/dt` (design notes,
//! section 1), has no DC part from `d psi_s/dt` in a steady state (the flux is bounded),
//! so the voltage's DC part is `-Rs o`: the offset is observable wherever the stator field
//! turns. (A stationary DC current drags the rotor like DC-injection braking; its rotor
//! currents make a stator flux that is itself stationary, so it adds nothing to the DC
//! voltage.) With an estimate `o_hat` subtracted, the DC voltage is `Rs (o_hat - o)`, zero
//! exactly at `o_hat = o`; the inverter's dead-time error has no DC part for a current
//! with none, so it changes the loop's gain a little, never its fixed point. At
//! `w_s = 0` the offset's DC voltage is the same as a resistance error's and no stator
//! quantity separates them: the tracker holds its estimate below
//! [`OffsetTrackerConfig::min_frequency`].
//!
//! At standstill (the Rs identification with the frame held) the offset's d-axis part
//! reads as a resistance, `Rs_hat = Rs (1 - o_d / i_sd)`: what the start's switches-off
//! measurement is for. The tracker is for the drift after it.
//!
//! ## The estimator: the fundamental and the DC part separated adaptively
//!
//! The tracker reads `u = v - Rs_hat i` in the stationary frame: `v` the voltage applied
//! over the period before this sample, `i` the sampled current with the drift estimate
//! already subtracted. Its fundamental is `d psi_s/dt`; its DC part is
//! `Rs (o_hat - o) + (Rs - Rs_hat) DC(i)`, where `DC(i)` is whatever DC the corrected
//! current still has (a ripple of the dq currents at f_s, from the speed loop, puts some
//! there; subtracting `Rs_hat i` keeps it out of the signature). The model is a
//! fundamental `x` of its own phase, turning at `w`, the stator frequency low-passed over
//! [`OFFSET_TRACKER_FREQUENCY_FILTER`], and the offset:
//!
//! ```text
//! x     <- e^{j w Ts} x                                  (stationary frame, V)
//! eps    = u - x
//! x     += mu_f Ts eps                                   (the fundamental)
//! o_hat -= (mu_o Ts / Rs) eps                            (the offset, stationary frame)
//! ```
//!
//! With `D = Rs (o_hat - o)` and `e_f` the fundamental's error, the errors obey (constant
//! `w_s = w`)
//!
//! ```text
//! d e_f/dt = j w_s e_f - mu_f (e_f + D)
//! d D/dt   = -mu_o (e_f + D)
//! ```
//!
//! whose characteristic polynomial is `s^2 + (mu_f + mu_o - j w_s) s - j w_s mu_o`. For
//! `mu_o << mu_f` its roots are `s_1 = -mu_f + j w_s` (the fundamental's tracking) and
//! `s_2 = -mu_o w_s^2 / (mu_f^2 + w_s^2) + j(...)`: the offset converges with the rate
//! `mu_o w_s^2 / (mu_f^2 + w_s^2)`, half of `mu_o` at `w_s = mu_f` and `mu_o` well above
//! it, in every quadrant (only `w_s^2` enters). [`OFFSET_TRACKER_FUNDAMENTAL_RATE`] is
//! `2 pi` rad/s (1 Hz, the running Rs law's lowest frequency too) and
//! [`OFFSET_TRACKER_TIME`] is `1 / mu_o`.
//!
//! **Why the model has its own phase.** The first version modelled the fundamental as a
//! constant vector in the drive's frame, `e^{j theta} V_hat`. The estimated frame wobbles
//! at f_s when the offset makes the torque ripple (at 60 rpm the orientation error swung
//! +/-3 degrees), and `e^{j theta} V_hat` then has a DC part of its own, `V_hat` times the
//! wobble's sideband, of the order of the signature itself and rotated by the sensorless
//! loop's phase: measured, the estimate spiralled away at 60 rpm (motoring and
//! regenerating) and converged only at 500 rpm. The true `u` has no DC part from any
//! wobble of the real flux (`d psi_s/dt` of a bounded flux averages to zero), and neither
//! has a model turning at a smooth frequency, so the residual's DC part is the offset's.
//! The turn uses cos = 1 - phi^2/2, sin = phi (1 - phi^2/6), phi = w Ts, whose angle is
//! phi + O(phi^5): a phase error would leave a residual at the fundamental.
//!
//! ## Gates, bound and what it reports
//!
//! The model follows the fundamental on every running step; the offset adapts only
//!
//! - with `|w|` at least [`OffsetTrackerConfig::min_frequency`]
//!   ([`OFFSET_TRACKER_MIN_FREQUENCY_HZ`], 1.5 Hz; below), or in the drive's far-side
//!   mode at least [`OffsetTrackerConfig::far_side_min_frequency`] (0.5 Hz), there at a
//!   tenth of the rate ("On the far side");
//! - with the references steady: the speed reference not ramping (the regeneration
//!   limit's hold, which moves the reference with the speed, is not a ramp: the drive's
//!   `ramping`, as for [`crate::inverter_tracker`]), and the torque-current
//!   reference within [`OffsetTrackerConfig::steady_band`] (0.1 i_sd*) of its low-pass
//!   over tau_r, as the running Rs law's gate ([`crate::rs_estimator`]); then for
//!   [`OFFSET_TRACKER_HOLDOFF`] time constants of the model (0.48 s) more, so that it has
//!   caught up (after a load step at 120 rpm its lag had put 70 mA into the estimate, and
//!   the drive held at the regeneration limit lost the orientation);
//! - with the residual's mean magnitude `|eps_alpha| + |eps_beta|` (low-passed over
//!   `1 / mu_f`) within [`OffsetTrackerConfig::residual_limit`], twice the DC voltage of
//!   the largest tolerated offset (`Rs offset_limit`): a larger residual is the
//!   fundamental still moving, or harmonics and noise the signature does not stand above.
//!   On a machine of low resistance (the 50 hp acceptance machine, 0.087 ohm) the
//!   signature is small against the fundamental's movements: without this gate the
//!   recovery from a load step put amperes into the estimate. On the paper machine the
//!   steady mean is about 0.9 V against a limit of 3.4 V;
//! - with that mean at its floor: within 1.5 times its smallest recent value, a floor
//!   that follows the mean down at once and rises by `Rs offset_limit` in
//!   [`OFFSET_TRACKER_FLOOR_RISE_TIME`] (5 s). The model's error after a transient
//!   decays as `E e^{-mu_f t}` while turning at `w_s`, and what it leaves in the
//!   estimate is `(mu_o / Rs) E / sqrt(mu_f^2 + w_s^2)`: at 60 rpm (f_s = 3 Hz) a gate
//!   opening at 3 V of excess would take 14 mA; measured in `regen-60`, the recovery
//!   from the load step took 10 mA in 0.15 s and the speed estimate's largest error in
//!   the window went from 0.61 to 1.86 rpm. With the floor it opens at a small excess
//!   over the noise (0.9 V here), and regen-60 is as without the tracker. The band is
//!   half the floor and at least [`OFFSET_TRACKER_FLOOR_BAND`] `Rs offset_limit` (0.67 V
//!   on the paper machine). Half the floor alone made the gate as fine as the noise: where
//!   the noise is small against the sensorless loop's own wobble at f_s (with a slow task,
//!   whose mean of `u` over the slow period takes the noise down by its square root) the
//!   gate opened and shut with the wobble's phase, and what it let through was biased:
//!   on the far side (60 rpm, 4.5 N m regenerating, 20 mA drifting in) the speed
//!   estimate ended 2.9 rpm off with a 1 ms slow task and 4.5 rpm with 1.6 ms, against
//!   1.4-1.6 rpm with the least band (0.9 rpm at the control rate either way), and with
//!   the gate's floor test off, 1.5 rpm.
//!
//! **Why 1.5 Hz and not the running Rs law's 1 Hz.** The signature above is the open
//! machine's. In the closed sensorless loop a DC current is also a torque ripple at f_s,
//! and at 1-2 Hz that is inside the speed loop's band (25 rad/s) and near the orientation
//! mode's, which regeneration damps least (its `w_s w_slip < 0` term, [`crate::orientation`]).
//! The loop's answer at f_s comes back as DC in `u`, turned by the loop's phase, and the
//! estimate no longer converges to the offset. Measured with no offset drift at all (the
//! robustness matrix's sensors, no regeneration limit, running Rs law; `cargo run
//! --release -p acim-sim --example robust_case -- 0 <rpm> <motor|regen> <load> running
//! drive.loops.regen_min_frequency_hz=0`), the largest estimate after the load step was, with
//! the gate at 1 Hz:
//!
//! | point | f_s | largest estimate | the case |
//! |---|---|---|---|
//! | 60 rpm, 1.0 N m regenerating | 1.33 Hz | 51 mA | lost (8.2 rpm of estimation error; 0.39 rpm without the tracker) |
//! | 75 rpm, 1.5 N m regenerating | 1.49 Hz | 46 mA | lost (7.3 rpm; runs at 1.37 Hz) |
//! | 60 rpm, 4.5 N m regenerating (far side) | -1.05 Hz | 9.5 mA; with the plant's Rs drifting +30 %, 43 mA | held; with the drift, lost, then an overload trip |
//! | 30 rpm, 0.5 N m motoring | 1.34 Hz | 11.6 mA | held |
//! | 60 rpm, 0.5 and 0.25 N m regenerating | 1.67, 1.84 Hz | 6.9, 7.6 mA | held |
//! | 45, 54, 66 rpm, no load | 1.5-2.2 Hz | 0.8-1.2 mA | held |
//!
//! With the gate at 1.5 Hz the three lost or faulted cases hold (0.34 rpm, 0.12 rpm and
//! -0.35 rpm of estimation error, the estimates under 1.4 mA), and item 3's points at
//! 1.67 and 1.84 Hz are tracked as before. Below 1.5 Hz the drift is followed only on the
//! far side, slowly (below).
//! The drive's regeneration limit holds regeneration at 1.5 Hz by default, the same
//! frequency, so the tracker works at the limited points (it turns on and off there as
//! the frequency wobbles about the gate, which only pauses the adaptation). Until it
//! read the drive's `ramping` flag, the tracker took the hold's moving reference for a
//! ramp and never adapted there: 20 mA drifting in at 60 rpm regenerating
//! 1.5 N m (held at 1.5 Hz) read 1.17 rpm of estimation error, now 0.18 rpm (the
//! robustness matrix's defaults).
//!
//! ## On the far side
//!
//! In the drive's far-side mode (60 rpm regenerating 4.5 N m: f_s = -1.05 Hz, [`crate::drive`])
//! the offset adapts from [`OFFSET_TRACKER_FAR_SIDE_MIN_FREQUENCY_HZ`] (0.5 Hz, where the
//! far-side term's fade starts) with `1 / mu_o` = [`OFFSET_TRACKER_FAR_SIDE_TIME`] (10 s)
//! instead of 1 s. Untracked, 20 mA there make a torque ripple at f_s that the rotor's
//! inertia turns into a speed swing of +/-18 rpm (46-83 rpm, against 58-60 rpm without the
//! offset), the rotor flux swings +/-5.6 %, and the swing rectifies into -5.4 rpm of
//! estimation error; the error grows with the offset's magnitude whatever its direction
//! (5, 10, 20 mA: -0.9, -2.8, -5.9 rpm from the nominal row's +0.45).
//!
//! **Measured signature.** With the drift present and not adapted, the residual's DC part
//! (the mean of `eps` over 2 s, divided by the model's DC transfer `-j w / (mu_f - j w)`,
//! less the nominal run's) is `G (o_hat - o)` with `G` = 32-38 ohm at +18 to +31 degrees:
//! 3.3 times the open machine's `Rs` (10.5 ohm), turned but within 90 degrees, so a slow
//! adaptation converges. A fast one does not: the sensorless loop's slowest pair there
//! (-1.40 +/- 4.74j rad/s, `acim_sim::linear`) is seen from the stationary frame at
//! `|w_s| - 4.74` = 1.9 rad/s, inside the band of an estimate that adapts at ~1 /s, and the
//! two couple. With the far-side band at the above-gate rate (1 s) the nominal far-side
//! row, with no drift at all, spiralled out to 39 mA in 5 s; at 3 s the estimate circled
//! the true offset at a radius of 6-12 mA with a 6 s period; at 5 s the plant's Rs drift
//! row (+30 % over 20 s) read as an offset (-2.43 rpm, failed); at 10 s every far-side row
//! of the matrix holds as before or better (the Rs drift row 0.38 -> 0.18 rpm), the nominal
//! row's estimate stays under 1 mA over 150 s, and 20 mA drifting in over 4-5 s are held
//! within 2 rpm from 15 s (2 s means: -4.2 rpm at 7-9 s, -2.3 at 13-15 s, -1.8 at 15-17 s,
//! -0.95 at 17-19 s, within 0.5 rpm from 23 s; untracked -5.4 and -4.1 at 7-9 and
//! 17-19 s). `cargo run --release -p acim-sim --example robust_case -- 10 60 regen 4.5
//! running drive.loops.regen_min_frequency_hz=1.5 duration_s=40` with `CSV=`; test
//! `offset_drift_is_tracked_slowly_on_the_far_side`. A sensor's thermal drift takes
//! minutes; the matrix's 1 s ramp is still not followed within its window (2-4 s after).
//!
//! The estimate is clamped to `offset_limit` on each axis; reaching it is a current-sensor
//! fault (the drive's supervision), as an idle offset beyond it is at the start. A drift
//! is followed to the bound (tested: `fault-offset-drift-running`); an offset step far
//! beyond the limit is accepted only once the residual's floor has risen to its DC
//! voltage (5 s per `Rs offset_limit`), and until then shows as a torque ripple at f_s.
//!
//! ## With a slow task
//!
//! With the drive's slow task ([`LoopSettings::slow_period`](crate::LoopSettings::slow_period)) the model and
//! the estimate update once per slow period `T`, on the mean of `u` over it (the fast
//! path only sums `u`, two products and two sums a period). The mean keeps the DC part
//! exactly and the fundamental as a phasor turning by `w T` per slow period (shrunk by
//! `sinc(w T / 2)`, which the model's own amplitude absorbs), so the estimator above runs
//! unchanged at the period `T` (its rates, hold-off and floor are designed for it); the
//! model turns by `w T` ([`OffsetTrackerConfig::large_turn`]: 0.94 rad at 150 Hz and
//! 1 ms, where the control rate's series would be off by a residual at the fundamental),
//! in f32 by the series of an eighth of the angle squared three times ([`large_turn`]:
//! within 2e-6 of the sin/cos up to 4 rad, no sin/cos call in the slow task), in fixed
//! point by the drive's sin/cos table.
//! The estimate the drive subtracts changes once per slow period, by at most its rate
//! times `T`.

use crate::frames::{AlphaBeta, SinCos};
use crate::num::{Angles, FineIntegrator, Num, PerUnitBases, Units};

/// The fundamental tracker's rate `mu_f`, rad/s: 1 Hz (module docs).
pub const OFFSET_TRACKER_FUNDAMENTAL_RATE: f32 = 2.0 * core::f32::consts::PI;
/// The offset adapts from this stator frequency up, Hz: above the band where the
/// sensorless loop's answer to a DC current turns its signature (module docs).
pub const OFFSET_TRACKER_MIN_FREQUENCY_HZ: f32 = 1.5;
/// The offset's time constant `1 / mu_o` well above 1 Hz, s (module docs).
pub const OFFSET_TRACKER_TIME: f32 = 1.0;
/// In the drive's far-side mode the offset adapts from this stator frequency up, Hz
/// (module docs, "On the far side").
pub const OFFSET_TRACKER_FAR_SIDE_MIN_FREQUENCY_HZ: f32 = 0.5;
/// The offset's time constant `1 / mu_o` below [`OFFSET_TRACKER_MIN_FREQUENCY_HZ`] in the
/// far-side mode, s (module docs, "On the far side").
pub const OFFSET_TRACKER_FAR_SIDE_TIME: f32 = 10.0;
/// Once the references are steady again (no speed ramp, the torque-current reference
/// within its band) the offset waits this many time constants of the fundamental's model
/// (its lag behind a moving fundamental is a residual at the fundamental).
pub const OFFSET_TRACKER_HOLDOFF: f32 = 3.0;
/// The residual gate: this many times the DC voltage of the largest tolerated offset.
pub const OFFSET_TRACKER_RESIDUAL_FACTOR: f32 = 2.0;
/// The residual's floor (its smallest recent mean, the noise and harmonics a settled model
/// leaves) rises by `Rs offset_limit` in this time, s: a residual that stays above it
/// (a large offset step) is accepted after about this time per `Rs offset_limit`.
pub const OFFSET_TRACKER_FLOOR_RISE_TIME: f32 = 5.0;
/// The floor gate's least band above the floor, in `Rs offset_limit` (module docs): a
/// transient's excess within it leaves at most this times `offset_limit / (T |mu_f + j
/// w_s|)` in the estimate (`T` = [`OFFSET_TRACKER_TIME`]), 3.5 % of the limit at the 1.5 Hz
/// gate, a tenth of that on the far side.
pub const OFFSET_TRACKER_FLOOR_BAND: f32 = 0.4;
/// The model frequency's low-pass time constant, s: the stator frequency's wobble at
/// f_s (the sensorless loop's own ripple) must not turn the model's phase.
pub const OFFSET_TRACKER_FREQUENCY_FILTER: f32 = 0.1;

/// The tracker's design (immutable; [`crate::design::DriveDesign`] builds it).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OffsetTrackerConfig<N: Num + FineIntegrator = f32> {
    /// Track at all ([`TrackerSettings::offset_tracking`](crate::TrackerSettings::offset_tracking)).
    pub enabled: bool,
    /// `mu_f Ts`, per step.
    pub fundamental_gain: N::Gain,
    /// `mu_o Ts / Rs`, A per V per step (fixed point: into the finer integrator format).
    pub offset_gain: N::Gain,
    /// The same on the far side below `min_frequency`, with `1 / mu_o` =
    /// [`OFFSET_TRACKER_FAR_SIDE_TIME`].
    pub far_side_offset_gain: N::Gain,
    /// The model frequency's low-pass gain, `Ts / OFFSET_TRACKER_FREQUENCY_FILTER`.
    pub frequency_filter: N::Gain,
    /// `Ts`, s (rad per step from rad/s): the series turn's angle.
    pub ts: N::Gain,
    /// `Ts / 8`, s: the large turn's eighth of the angle.
    pub eighth_ts: N::Gain,
    /// `Ts` as the angle gain of [`crate::num::Angles::advance`]: the large turn's by
    /// sin/cos (fixed point).
    pub turn: N::Gain,
    /// Turn the model by the large turn ([`large_turn`]) instead of the series: the
    /// tracker runs once per slow period, whose angle `w T` reaches a radian in field
    /// weakening (the series' phase error, `phi^5/120`, would then be a residual at the
    /// fundamental).
    pub large_turn: bool,
    /// 1/6 (the sine's cubic term).
    pub one_sixth: N::Gain,
    /// The large turn's other series terms: 1/24 and 1/720 (the cosine's), 1/120 and
    /// 1/5040 (the sine's).
    pub turn_terms: [N::Gain; 4],
    /// Adapts from this |w_s|, rad/s electrical.
    pub min_frequency: N,
    /// In the drive's far-side mode, adapts from this |w_s| (at the far-side rate below
    /// `min_frequency`), rad/s electrical.
    pub far_side_min_frequency: N,
    /// Adapts this many steps after the references became steady: three time constants
    /// of the fundamental's model ([`OFFSET_TRACKER_HOLDOFF`]).
    pub holdoff_steps: u32,
    /// The torque-current reference's low-pass gain over tau_r, `Ts / tau_r` (as the
    /// running Rs law's steadiness gate, [`crate::rs_estimator`]).
    pub steady_filter: N::Gain,
    /// The torque-current reference counts as steady within this of its low-pass, A.
    pub steady_band: N,
    /// The residual's mean magnitude `|eps_alpha| + |eps_beta|` must be at most this, V:
    /// [`OFFSET_TRACKER_RESIDUAL_FACTOR`] times the DC voltage of the largest tolerated
    /// offset, `Rs offset_limit` (a larger residual is the fundamental moving, or noise
    /// and harmonics the offset's signature does not stand above).
    pub residual_limit: N,
    /// The floor gate's least band above the floor, V: [`OFFSET_TRACKER_FLOOR_BAND`]
    /// times `Rs offset_limit`.
    pub floor_band_min: N,
    /// The residual floor's rise per step, V: `Rs offset_limit Ts /
    /// OFFSET_TRACKER_FLOOR_RISE_TIME`.
    pub floor_rise: N,
    /// The estimate's bounds on each axis, -offset_limit and offset_limit, A (in the
    /// integrator format).
    pub bounds: (N::Fine, N::Fine),
}

impl OffsetTrackerConfig<f32> {
    /// The design for period `ts` (s), the nominal stator resistance `rs` (ohm), the
    /// largest tolerated offset `offset_limit` (A), the flux current (A) and the rotor
    /// time constant `tau_r` (s).
    pub fn new(
        enabled: bool,
        ts: f32,
        rs: f32,
        offset_limit: f32,
        flux_current: f32,
        tau_r: f32,
    ) -> Self {
        Self {
            enabled,
            fundamental_gain: (OFFSET_TRACKER_FUNDAMENTAL_RATE * ts).min(1.0),
            offset_gain: ts / (OFFSET_TRACKER_TIME * rs),
            far_side_offset_gain: ts / (OFFSET_TRACKER_FAR_SIDE_TIME * rs),
            frequency_filter: (ts / OFFSET_TRACKER_FREQUENCY_FILTER).min(1.0),
            ts,
            eighth_ts: ts / 8.0,
            turn: ts,
            large_turn: false,
            one_sixth: 1.0 / 6.0,
            turn_terms: [1.0 / 24.0, 1.0 / 720.0, 1.0 / 120.0, 1.0 / 5040.0],
            min_frequency: 2.0 * core::f32::consts::PI * OFFSET_TRACKER_MIN_FREQUENCY_HZ,
            far_side_min_frequency: 2.0
                * core::f32::consts::PI
                * OFFSET_TRACKER_FAR_SIDE_MIN_FREQUENCY_HZ,
            holdoff_steps: (OFFSET_TRACKER_HOLDOFF / (OFFSET_TRACKER_FUNDAMENTAL_RATE * ts)) as u32,
            steady_filter: (ts / tau_r).min(1.0),
            steady_band: crate::rs_estimator::RUNNING_STEADY_TORQUE_FRACTION * flux_current.abs(),
            residual_limit: OFFSET_TRACKER_RESIDUAL_FACTOR * rs * offset_limit,
            floor_band_min: OFFSET_TRACKER_FLOOR_BAND * rs * offset_limit,
            floor_rise: rs * offset_limit * ts / OFFSET_TRACKER_FLOOR_RISE_TIME,
            bounds: (-offset_limit, offset_limit),
        }
    }
}

/// The fundamental's model (module docs, "The estimator").
#[derive(Clone, Copy, Debug, PartialEq)]
struct Model<N: Num> {
    /// The fundamental's model, stationary frame, V.
    fundamental: AlphaBeta<N>,
    /// Its frequency, the stator frequency low-passed, rad/s.
    frequency: N,
}

/// Whether the references are steady (module docs, "Gates, bound and what it reports").
#[derive(Clone, Copy, Debug, PartialEq)]
struct Steadiness<N: Num> {
    /// Steps since the references were last unsteady (saturating).
    steady_steps: u32,
    /// The torque-current reference low-passed over tau_r, A.
    torque_reference_slow: N,
}

/// The offset estimate's integrators, in the finer integrator format.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Integrators<N: Num + FineIntegrator> {
    /// The alpha offset's integrator, A (fine format).
    alpha: N::Fine,
    /// The beta offset's integrator, A (fine format).
    beta: N::Fine,
}

/// The tracker's state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OffsetTracker<N: Num + FineIntegrator = f32> {
    /// The fundamental's model and its frequency.
    model: Model<N>,
    /// The steadiness gate's filter and count.
    steadiness: Steadiness<N>,
    /// The offset estimate's integrators.
    integrators: Integrators<N>,
    /// With a slow task: the period's `u` summed, each weighted by 1 / the slow divider
    /// (the mean over the slow period at its tick), V.
    sum: AlphaBeta<N>,
    /// The residual's magnitude low-passed over 1 / mu_f, V.
    pub residual: N,
    /// The residual's floor: its smallest recent mean, rising slowly, V.
    pub residual_floor: N,
    /// The offset estimate `o_hat` the drive subtracts from the measured current, A.
    pub offset: AlphaBeta<N>,
    /// The estimate sits at its bound (a current-sensor fault).
    pub at_bound: bool,
    /// The last step adapted the offset.
    pub adapting: bool,
}

impl<N: Num + FineIntegrator> Default for OffsetTracker<N> {
    fn default() -> Self {
        Self {
            model: Model {
                fundamental: AlphaBeta {
                    alpha: N::ZERO,
                    beta: N::ZERO,
                },
                frequency: N::ZERO,
            },
            steadiness: Steadiness {
                steady_steps: 0,
                torque_reference_slow: N::ZERO,
            },
            integrators: Integrators {
                alpha: N::to_fine(N::ZERO),
                beta: N::to_fine(N::ZERO),
            },
            sum: AlphaBeta {
                alpha: N::ZERO,
                beta: N::ZERO,
            },
            residual: N::ZERO,
            residual_floor: N::ZERO,
            offset: AlphaBeta {
                alpha: N::ZERO,
                beta: N::ZERO,
            },
            at_bound: false,
            adapting: false,
        }
    }
}

/// What the tracker reads each step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OffsetTrackerInputs<N: Num = f32> {
    /// The voltage applied over the last period less Rs_hat times the corrected current,
    /// stationary frame, V.
    pub u_ab: AlphaBeta<N>,
    /// The stator frequency w_s, rad/s electrical.
    pub stator_frequency: N,
    /// False while magnetizing.
    pub running: bool,
    /// The speed reference ramps.
    pub ramping: bool,
    /// The last torque-current reference, A.
    pub i_sq_ref: N,
    /// The drive's far-side mode.
    pub far_side: bool,
}

impl<N: Num + FineIntegrator + Angles> OffsetTracker<N> {
    /// With a slow task, every period: adds this period's `u` (V) weighted by `weight`
    /// (1 / the slow divider) to the slow period's mean.
    #[inline(always)]
    pub fn accumulate(&mut self, u: AlphaBeta<N>, weight: N::Gain) {
        self.sum = AlphaBeta {
            alpha: self.sum.alpha + N::gain(weight, u.alpha),
            beta: self.sum.beta + N::gain(weight, u.beta),
        };
    }

    /// The slow period's mean of `u` (V); the next period starts a new one.
    #[inline(always)]
    pub fn take_mean(&mut self) -> AlphaBeta<N> {
        let mean = self.sum;
        self.sum = AlphaBeta {
            alpha: N::ZERO,
            beta: N::ZERO,
        };
        mean
    }

    /// How far the residual may stand above its floor for the offset to adapt, V: half
    /// the floor, and at least [`OffsetTrackerConfig::floor_band_min`] (module docs).
    #[inline(always)]
    fn floor_band(&self, cfg: &OffsetTrackerConfig<N>) -> N {
        let half = self.residual_floor.half();
        if half > cfg.floor_band_min {
            half
        } else {
            cfg.floor_band_min
        }
    }

    /// One step on the inputs `x` (every control period, or once per slow period on the
    /// period's mean of `u`, with `cfg.large_turn`); in fixed point `sincos` makes the
    /// large turn ([`Angles::TURN_BY_PRODUCTS`]).
    #[inline(always)]
    pub fn update<S: SinCos<N>>(
        &mut self,
        cfg: &OffsetTrackerConfig<N>,
        x: &OffsetTrackerInputs<N>,
        sincos: &mut S,
    ) {
        let &OffsetTrackerInputs {
            u_ab,
            stator_frequency,
            running,
            ramping,
            i_sq_ref,
            far_side,
        } = x;
        self.adapting = false;
        if !(cfg.enabled && running) {
            return;
        }
        let w = self.model.frequency
            + N::gain(
                cfg.frequency_filter,
                stator_frequency - self.model.frequency,
            );
        self.model.frequency = w.finite_or(N::ZERO);
        // the model turns by phi = w Ts: cos ~ 1 - phi^2/2, sin ~ phi (1 - phi^2/6), whose
        // angle is phi + O(phi^5) (a phase error would be a residual at the fundamental);
        // once per slow period, by the large turn
        let (c, s) = if cfg.large_turn && N::TURN_BY_PRODUCTS {
            large_turn(cfg, self.model.frequency)
        } else if cfg.large_turn {
            let turn = N::advance(N::Angle::default(), self.model.frequency, cfg.turn);
            let sc = sincos.sin_cos(turn);
            (sc.cos, sc.sin)
        } else {
            let phi = N::gain(cfg.ts, self.model.frequency);
            let phi2 = phi * phi;
            (
                N::ONE - phi2.half(),
                phi - phi * N::gain(cfg.one_sixth, phi2),
            )
        };
        let x = self.model.fundamental;
        let x = AlphaBeta {
            alpha: x.alpha * c - x.beta * s,
            beta: x.beta * c + x.alpha * s,
        };
        let eps = AlphaBeta {
            alpha: u_ab.alpha - x.alpha,
            beta: u_ab.beta - x.beta,
        };
        if !N::all_finite([eps.alpha, eps.beta]) {
            self.model.fundamental = AlphaBeta {
                alpha: N::ZERO,
                beta: N::ZERO,
            };
            return;
        }
        self.model.fundamental = AlphaBeta {
            alpha: x.alpha + N::gain(cfg.fundamental_gain, eps.alpha),
            beta: x.beta + N::gain(cfg.fundamental_gain, eps.beta),
        };
        let r = eps.alpha.abs() + eps.beta.abs();
        self.residual = self.residual + N::gain(cfg.fundamental_gain, r - self.residual);
        let floor = self.residual_floor + cfg.floor_rise;
        self.residual_floor = if self.residual < floor {
            self.residual
        } else {
            floor
        };
        let slow = self.steadiness.torque_reference_slow
            + N::gain(
                cfg.steady_filter,
                i_sq_ref - self.steadiness.torque_reference_slow,
            );
        self.steadiness.torque_reference_slow = slow.finite_or(N::ZERO);
        let steady =
            !ramping && (i_sq_ref - self.steadiness.torque_reference_slow).abs() <= cfg.steady_band;
        self.steadiness.steady_steps = if steady {
            self.steadiness.steady_steps.saturating_add(1)
        } else {
            0
        };
        let f = self.model.frequency.abs();
        let gain = if f >= cfg.min_frequency {
            Some(cfg.offset_gain)
        } else if far_side && f >= cfg.far_side_min_frequency {
            Some(cfg.far_side_offset_gain)
        } else {
            None
        };
        // (a plain condition, not a closure: LLVM kept the closure out of line, outside
        // the interrupt's CCM SRAM)
        let settled = self.steadiness.steady_steps >= cfg.holdoff_steps
            && self.residual <= cfg.residual_limit
            && self.residual <= self.residual_floor + self.floor_band(cfg);
        if let (Some(g), true) = (gain, settled) {
            let (lo, hi) = cfg.bounds;
            let (a, at_a) = N::fine_step(self.integrators.alpha, g, eps.alpha, false, lo, hi);
            let (b, at_b) = N::fine_step(self.integrators.beta, g, eps.beta, false, lo, hi);
            self.integrators.alpha = a;
            self.integrators.beta = b;
            self.at_bound = at_a || at_b;
            self.adapting = true;
            self.offset = AlphaBeta {
                alpha: N::from_fine(a),
                beta: N::from_fine(b),
            };
        }
    }
}

/// cos and sin of the slow period's turn `phi = w T` (`w` rad/s electrical): the series
/// of `x = phi/8` (the cosine to `x^6`, the sine to `x^7`), squared three times as a
/// unit phasor: within 2e-6 of the sin/cos up to 4 rad (320 Hz at a 2 ms slow period),
/// where `x` is 0.5 and the series are within 1e-7 (the rest is f32 rounding). Fourteen multiplications, where a
/// software sin/cos with its angle wrap costs several times that on a Cortex-M4.
#[inline(always)]
pub fn large_turn<N: Num + FineIntegrator>(cfg: &OffsetTrackerConfig<N>, w: N) -> (N, N) {
    let x = N::gain(cfg.eighth_ts, w);
    let x2 = x * x;
    let [c4, c6, s5, s7] = cfg.turn_terms;
    let x4 = x2 * x2;
    let mut c = N::ONE - x2.half() + x4 * (N::gain(c4, N::ONE) - N::gain(c6, x2));
    let mut s =
        x - x * N::gain(cfg.one_sixth, x2) + x * x4 * (N::gain(s5, N::ONE) - N::gain(s7, x2));
    for _ in 0..3 {
        let cs = c * s;
        c = c * c - s * s;
        s = cs + cs;
    }
    (c, s)
}

impl OffsetTrackerConfig<f32> {
    /// This design in the arithmetic `N` with the bases `b`: its offset gain takes a
    /// voltage into the finer integrator format of a current. `None` if a gain is not
    /// representable.
    pub fn convert<N: Num + Units + FineIntegrator + Angles>(
        &self,
        b: &PerUnitBases,
    ) -> Option<OffsetTrackerConfig<N>> {
        let g = N::gain_from_f32;
        let limit = N::to_fine(N::from_f32(self.bounds.1 / b.current));
        let lower = N::to_fine(N::from_f32(self.bounds.0 / b.current));
        Some(OffsetTrackerConfig {
            enabled: self.enabled,
            fundamental_gain: g(self.fundamental_gain)?,
            offset_gain: g(self.offset_gain * b.voltage / b.current * N::FINE_SCALE)?,
            far_side_offset_gain: g(
                self.far_side_offset_gain * b.voltage / b.current * N::FINE_SCALE
            )?,
            frequency_filter: g(self.frequency_filter)?,
            ts: g(self.ts * b.frequency)?,
            eighth_ts: g(self.eighth_ts * b.frequency)?,
            turn: N::angle_gain(b.frequency * self.turn)?,
            large_turn: self.large_turn,
            one_sixth: g(self.one_sixth)?,
            turn_terms: [
                g(self.turn_terms[0])?,
                g(self.turn_terms[1])?,
                g(self.turn_terms[2])?,
                g(self.turn_terms[3])?,
            ],
            min_frequency: N::from_f32(self.min_frequency / b.frequency),
            far_side_min_frequency: N::from_f32(self.far_side_min_frequency / b.frequency),
            holdoff_steps: self.holdoff_steps,
            steady_filter: g(self.steady_filter)?,
            steady_band: N::from_f32(self.steady_band / b.current),
            residual_limit: N::from_f32(self.residual_limit / b.voltage),
            floor_band_min: N::from_f32(self.floor_band_min / b.voltage),
            floor_rise: N::from_f32(self.floor_rise / b.voltage),
            bounds: (lower, limit),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TS: f32 = 2.0e-4;
    const RS: f32 = 10.5;
    const LIMIT: f32 = 0.16;

    /// A synthetic closed loop: the voltage the tracker reads is a fundamental of
    /// `amplitude` V at `w` rad/s plus Rs (o_hat - o) (module docs), for `seconds`.
    fn run(w: f32, amplitude: f32, o: (f32, f32), seconds: f32) -> OffsetTracker {
        run_ramped(w, amplitude, o, seconds, 0.0)
    }

    /// [`run`] with the offset reaching `o` linearly over `ramp` seconds.
    fn run_ramped(w: f32, amplitude: f32, o: (f32, f32), seconds: f32, ramp: f32) -> OffsetTracker {
        run_in(w, amplitude, o, seconds, ramp, false)
    }

    /// [`run_ramped`] in or out of the drive's far-side mode.
    fn run_in(
        w: f32,
        amplitude: f32,
        o: (f32, f32),
        seconds: f32,
        ramp: f32,
        far_side: bool,
    ) -> OffsetTracker {
        let cfg = OffsetTrackerConfig::new(true, TS, RS, LIMIT, 1.5, 0.067);
        let mut t = OffsetTracker::default();
        let mut theta = 0.0f32;
        for k in 0..(seconds / TS) as usize {
            let f = if ramp > 0.0 {
                (k as f32 * TS / ramp).min(1.0)
            } else {
                1.0
            };
            let o = (f * o.0, f * o.1);
            // wrapped: an f32 angle in the thousands of radians would round its steps
            theta = (theta + w * TS) % (2.0 * core::f32::consts::PI);
            let (s, c) = theta.sin_cos();
            let u = AlphaBeta {
                alpha: amplitude * c + RS * (t.offset.alpha - o.0),
                beta: amplitude * s + RS * (t.offset.beta - o.1),
            };
            t.update(
                &cfg,
                &OffsetTrackerInputs {
                    u_ab: u,
                    stator_frequency: w,
                    running: true,
                    ramping: false,
                    i_sq_ref: 0.0,
                    far_side,
                },
                &mut crate::frames::FastSinCos,
            );
        }
        t
    }

    /// [`run`] with a slow task: the tracker sums `u` every period and adapts once per
    /// `divider` periods on the mean, turning its model by the large turn.
    fn run_slow(
        w: f32,
        amplitude: f32,
        o: (f32, f32),
        seconds: f32,
        divider: u32,
    ) -> OffsetTracker {
        let slow_ts = TS * divider as f32;
        let cfg = OffsetTrackerConfig {
            large_turn: true,
            ..OffsetTrackerConfig::new(true, slow_ts, RS, LIMIT, 1.5, 0.067)
        };
        let mut t = OffsetTracker::default();
        let mut theta = 0.0f32;
        for k in 0..(seconds / TS) as usize {
            theta = (theta + w * TS) % (2.0 * core::f32::consts::PI);
            let (s, c) = theta.sin_cos();
            let u = AlphaBeta {
                alpha: amplitude * c + RS * (t.offset.alpha - o.0),
                beta: amplitude * s + RS * (t.offset.beta - o.1),
            };
            t.accumulate(u, 1.0 / divider as f32);
            if (k + 1) % divider as usize == 0 {
                let mean = t.take_mean();
                t.update(
                    &cfg,
                    &OffsetTrackerInputs {
                        u_ab: mean,
                        stator_frequency: w,
                        running: true,
                        ramping: false,
                        i_sq_ref: 0.0,
                        far_side: false,
                    },
                    &mut crate::frames::FastSinCos,
                );
            }
        }
        t
    }

    /// The large turn against the sin/cos (f64 on the host): within 2e-6 up to 4 rad
    /// (320 Hz at a 2 ms slow period) either way, about 16 f32 roundings.
    #[test]
    fn the_large_turn_follows_the_sin_cos() {
        let cfg = OffsetTrackerConfig {
            large_turn: true,
            ..OffsetTrackerConfig::new(true, 1e-3, RS, LIMIT, 1.5, 0.067)
        };
        for k in -400..=400 {
            let phi = k as f32 * 0.01;
            let (c, s) = large_turn(&cfg, phi / 1e-3);
            let (s0, c0) = (phi as f64).sin_cos();
            let err = (c as f64 - c0).abs().max((s as f64 - s0).abs());
            assert!(err < 2e-6, "phi {phi}: ({c}, {s}) against ({c0}, {s0})");
        }
    }

    /// Once per 1 ms slow period on the mean: the offset is found as at the control rate,
    /// from 2 Hz to 50 Hz either way, and at 150 Hz (field weakening: the model turns by
    /// 0.94 rad per slow period, by the large turn). At the control rate the series
    /// turn's amplitude error (phi^4/24 per period, 5e-5 at 150 Hz against a correction
    /// of 1.3e-3) leaves a 10 V residual at the fundamental there, above the gate: that
    /// tracker holds its estimate in deep field weakening.
    #[test]
    fn at_a_1_khz_slow_task_it_converges_from_the_means() {
        for f_hz in [2.0f32, 10.0, 50.0, 150.0, -50.0] {
            let w = 2.0 * core::f32::consts::PI * f_hz;
            let check = |kind: &str, t: OffsetTracker| {
                assert!(
                    (t.offset.alpha - 0.03).abs() < 2e-3 && (t.offset.beta + 0.02).abs() < 2e-3,
                    "{kind} {f_hz} Hz: {:?} residual {} floor {}",
                    t.offset,
                    t.residual,
                    t.residual_floor
                );
                assert!(!t.at_bound);
            };
            check("slow", run_slow(w, 200.0, (0.03, -0.02), 8.0, 5));
            if f_hz.abs() <= 50.0 {
                check("fast", run(w, 200.0, (0.03, -0.02), 8.0));
            }
        }
    }

    #[test]
    fn converges_in_both_directions_above_the_gate() {
        for hz in [-50.0, -1.6, 1.6, 5.0, 50.0] {
            let w = 2.0 * core::f32::consts::PI * hz;
            let t = run(w, 20.0 + 3.0 * hz.abs(), (0.02, -0.0115), 8.0);
            assert!(
                (t.offset.alpha - 0.02).abs() < 1e-3,
                "{hz} Hz: {:?}",
                t.offset
            );
            assert!(
                (t.offset.beta + 0.0115).abs() < 1e-3,
                "{hz} Hz: {:?}",
                t.offset
            );
            assert!(!t.at_bound);
        }
    }

    #[test]
    fn holds_below_the_gate_and_while_magnetizing() {
        // below 1.5 Hz, including 1.0-1.5 Hz where the running Rs law adapts
        for hz in [0.5, -1.2, 1.4] {
            let t = run(2.0 * core::f32::consts::PI * hz, 5.0, (0.02, 0.0), 5.0);
            assert_eq!(t.offset.alpha, 0.0, "{hz} Hz");
        }
        let cfg = OffsetTrackerConfig::new(true, TS, RS, LIMIT, 1.5, 0.067);
        let mut t = OffsetTracker::default();
        let u = AlphaBeta {
            alpha: 1.0,
            beta: 1.0,
        };
        for _ in 0..1000 {
            t.update(
                &cfg,
                &OffsetTrackerInputs {
                    u_ab: u,
                    stator_frequency: 100.0,
                    running: false,
                    ramping: false,
                    i_sq_ref: 0.0,
                    far_side: false,
                },
                &mut crate::frames::FastSinCos,
            );
            t.update(
                &cfg,
                &OffsetTrackerInputs {
                    u_ab: u,
                    stator_frequency: 100.0,
                    running: true,
                    ramping: true,
                    i_sq_ref: 0.0,
                    far_side: false,
                },
                &mut crate::frames::FastSinCos,
            );
        }
        assert_eq!(t.offset.alpha, 0.0);
        assert!(!t.adapting);
    }

    #[test]
    fn on_the_far_side_it_adapts_from_half_a_hertz_at_a_tenth_of_the_rate() {
        // -1.05 Hz, the matrix's far side: the rate is mu_o w^2 / (mu_f^2 + w^2) with
        // 1 / mu_o = 10 s, 0.053 /s, so 41 % of the offset after 10 s
        let w = -2.0 * core::f32::consts::PI * 1.05;
        let t = run_in(w, 10.0, (0.02, 0.0), 10.0, 0.0, true);
        assert!((0.006..0.011).contains(&t.offset.alpha), "{:?}", t.offset);
        let t = run_in(w, 10.0, (0.02, -0.0115), 90.0, 0.0, true);
        assert!((t.offset.alpha - 0.02).abs() < 1e-3, "{:?}", t.offset);
        assert!((t.offset.beta + 0.0115).abs() < 1e-3, "{:?}", t.offset);
        // below 0.5 Hz, and out of the mode, it holds
        let t = run_in(
            -2.0 * core::f32::consts::PI * 0.4,
            10.0,
            (0.02, 0.0),
            10.0,
            0.0,
            true,
        );
        assert_eq!(t.offset.alpha, 0.0);
        let t = run_in(w, 10.0, (0.02, 0.0), 10.0, 0.0, false);
        assert_eq!(t.offset.alpha, 0.0);
    }

    #[test]
    fn a_drift_beyond_the_limit_sits_at_the_bound_and_nan_is_survived() {
        // a drift the tracker follows (its residual stays within the gate) until the bound;
        // a step that large would hold the residual above the gate instead
        let t = run_ramped(
            2.0 * core::f32::consts::PI * 10.0,
            50.0,
            (0.5, 0.0),
            20.0,
            20.0,
        );
        assert!(t.at_bound);
        assert!((t.offset.alpha - LIMIT).abs() < 1e-6);
        let cfg = OffsetTrackerConfig::new(true, TS, RS, LIMIT, 1.5, 0.067);
        let mut t = t;
        let nan = AlphaBeta {
            alpha: f32::NAN,
            beta: 0.0,
        };
        t.update(
            &cfg,
            &OffsetTrackerInputs {
                u_ab: nan,
                stator_frequency: f32::NAN,
                running: true,
                ramping: false,
                i_sq_ref: 0.0,
                far_side: false,
            },
            &mut crate::frames::FastSinCos,
        );
        t.update(
            &cfg,
            &OffsetTrackerInputs {
                u_ab: nan,
                stator_frequency: 60.0,
                running: true,
                ramping: false,
                i_sq_ref: 0.0,
                far_side: false,
            },
            &mut crate::frames::FastSinCos,
        );
        assert!(t.offset.alpha.is_finite() && t.offset.beta.is_finite());
        assert!(t.model.frequency.is_finite());
    }
}
