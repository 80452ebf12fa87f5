//! Dead or stuck current sensors, found from the voltage the drive applies and the current
//! the machine model predicts for it.
//!
//! The software over-current trip and the current loops only see what the sensors report:
//! a channel that reads its zero code (sense cable off, amplifier dead) or sticks at one
//! value (ADC input stuck) lets the true current run away while the samples look calm.
//! This block compares, channel by channel, how far each measured phase current moved over
//! a window of `window` PWM periods with how far the stator equation says it must have
//! moved under the applied voltage, and reports [`FaultReason::CurrentSensor`] when a
//! channel that should have moved did not follow.
//!
//! # The model (design notes section 3, paper eq. 9a-9b, inverse-Gamma form)
//!
//! In the drive's frame (d along its rotor-flux estimate, rotating at the stator frequency
//! w_s), with lambda_r the referred rotor flux on the d axis:
//!
//! ```text
//! sigma Ls di_d/dt = v_d - R_sigma i_d + sigma Ls w_s i_q + (R_R / L_M) lambda_r
//! sigma Ls di_q/dt = v_q - R_sigma i_q - sigma Ls w_s i_d - w_r lambda_r
//! ```
//!
//! with `R_sigma = Rs + R_R` (Rseq of the design notes), `R_R = (Lm/Lr)^2 Rr`,
//! `L_M = Lm^2/Lr` and `w_r = p Omega` (electrical rotor speed). Each period the block
//! predicts the current's increment over the period that just ended by forward Euler from
//! the previous sample (`delta = Ts/(sigma Ls) * (...)`), and the one-period residual
//! `eps = (i_k - i_{k-1}) - delta` feeds a slow low-pass filter, the *bias* (time
//! constant [`BIAS_TIME`]): the steady model error (an Rs or rotor-flux error, the
//! voltage the dead time eats, the frame's half-period lag behind the applied voltage) is
//! constant in this frame, and the bias removes it from the prediction. A failing channel
//! makes the residual grow within a few periods (the current loops wind up against a
//! current that does not respond, or the current's rotation is missing from a frozen
//! channel), far faster than the bias follows.
//!
//! # The decision, once per window
//!
//! Over a window the prediction is summed (`i_pred = i_start + sum(delta + bias)`, in the
//! frame), turned into phase currents with the frame's angle at the window's end (inverse
//! Park, inverse Clarke), and for every channel the drive measures:
//!
//! ```text
//! change   = i_pred,x(end) - i_meas,x(start)      what the channel should have moved
//! residual = i_meas,x(end) - i_pred,x(end)        what it failed to follow
//! fault when |change| > change_threshold
//!        and |residual| > response_ratio |change| + allowance
//! ```
//!
//! where `allowance = RESISTANCE_UNCERTAINTY R_sigma Ts/(sigma Ls) sum |i - i_filtered|`
//! over the window covers a resistance error on the part of the current the bias has not
//! yet followed (after a load step).
//!
//! A dead channel stays at zero while the model asks for the current loops' wound-up
//! voltage; a stuck one stays put while, at any speed above standstill, the current's
//! rotation alone moves every phase (|i| w_s window Ts: 2 A over 1.6 ms at 4 A and 50 Hz),
//! and at standstill the current loops' correction moves it. A healthy channel follows the
//! prediction to within the model's error, which scales with the change (the transient
//! inductance's error) and is covered by `response_ratio`.
//!
//! # Bound
//!
//! A channel that fails is reported at the end of the first whole window (after the
//! failure) over which its predicted change exceeds `change_threshold`: within two
//! windows (`2 window` periods, 16 at 5 kHz) of the first such window, at any speed.
//! - All channels dead: the current loops wind up against the missing current at once,
//!   so that window is the first: reported within `2 window` periods at any speed, loaded
//!   or not (tested at 0-1500 rpm).
//! - One channel stuck at its last reading: it reads its true value until the current
//!   moves, so the first such window comes once the current's rotation (or a commanded
//!   change) moves that phase by `change_threshold` within a window. A phase near its
//!   peak barely moves, so at speed this waits for the phase to leave its peak: measured
//!   in the synthetic tests below, 4-28 periods at 500 rpm and 1500 rpm, 20-132 periods
//!   at 60 rpm (where the current moves slowly and its drift from the stuck reading is
//!   small while it is not found).
//!
//! A channel whose predicted change stays below the threshold reads its true value within
//! that threshold and cannot drive the current away: every current change the drive
//! commands is a predicted change.
//!
//! # Use
//!
//! `no_std`, no allocation, no panic path and no division in [`SensorCheck::update`]; the
//! configuration is computed once at design time ([`SensorCheckConfig::new`], which
//! divides by validated, positive machine data). Generic over the crate's [`Num`]: the
//! f32 configuration comes from [`SensorCheckConfig::new`]; the fixed-point drive would
//! build its `Q24` configuration through its per-unit converter (its gains carry the
//! bases).

use crate::frames::{inverse_clarke, inverse_park, Dq, SinCosValue};
use crate::num::Num;
use crate::params::MachineParams;
use crate::supervisor::FaultReason;

/// The window, s: [`SensorCheckConfig::new`] takes the nearest whole number of periods,
/// at least [`MIN_WINDOW`] (8 periods at 5 kHz).
pub const WINDOW_TIME: f32 = 1.6e-3;
/// The fewest periods in a window.
pub const MIN_WINDOW: u32 = 4;
/// The most periods in a window.
pub const MAX_WINDOW: u32 = 64;
/// The smallest change a channel must be asked for before it is judged, as a fraction
/// of the drive's current limit I_max (0.15 I_max: 0.7 A for the paper's 4.67 A). Above
/// the residual's noise (two samples of about 0.1 % of full scale each) and the model's
/// unfiltered error within one window (a speed-estimate error of 50 rpm during a load
/// step on the paper machine: about 8 V, 0.33 A over 1.6 ms).
pub const CHANGE_FRACTION: f32 = 0.15;
/// A channel follows when its residual is at most this fraction of its predicted
/// change: room for a transient-inductance error of about +/-30 % and the forward-Euler
/// prediction's error over a window.
pub const RESPONSE_RATIO: f32 = 0.5;
/// Time constant of the bias filter, s: long against a window (a failure's residual is
/// absorbed by 1.6 ms / 40 ms = 4 % per window), short against the thermal drift of Rs
/// and the flux's settling.
pub const BIAS_TIME: f32 = 0.04;

/// The resistance error the check allows for, as a fraction of R_sigma (0.5: the
/// stator resistance 50 % off, the paper's Fig. 8 mismatch, with the rotor's right), on
/// the part of the current the bias filter has not yet followed: after a current step
/// the filter needs [`BIAS_TIME`] to learn the new `dR i`, and until then each period
/// adds `dR (i - i_filtered) Ts/(sigma Ls)` to the residual of a healthy channel.
pub const RESISTANCE_UNCERTAINTY: f32 = 0.5;

/// Why a configuration could not be built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SensorCheckError {
    /// The control period is not a positive finite number.
    ControlPeriod,
    /// The current limit is not a positive finite number.
    CurrentLimit,
    /// The machine's transient or magnetizing inductance is not positive and finite.
    Inductance,
}

/// The check's constants, from the machine data and the control period (design time).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SensorCheckConfig<N: Num = f32> {
    /// Ts / (sigma Ls), A/V (one period's current increment per volt).
    pub ts_over_sigma_ls: N::Gain,
    /// R_sigma = Rs + R_R, ohm.
    pub r_sigma: N::Gain,
    /// sigma Ls, H (the frame's rotation terms sigma Ls w_s i).
    pub sigma_ls: N::Gain,
    /// R_R / L_M, 1/s (the rotor flux's d-axis back-EMF).
    pub rr_over_lm: N::Gain,
    /// Periods per window.
    pub window: u32,
    /// The smallest predicted change per window that is judged, A.
    pub change_threshold: N,
    /// The largest residual of a following channel, as a fraction of its change.
    pub response_ratio: N::Gain,
    /// The bias filter's weight per period, Ts / [`BIAS_TIME`] (at most 1).
    pub bias_gain: N::Gain,
    /// The resistance error allowed on a current change the bias has not yet followed,
    /// times Ts/(sigma Ls): [`RESISTANCE_UNCERTAINTY`] R_sigma Ts/(sigma Ls), A per A and
    /// period.
    pub resistance_allowance: N::Gain,
}

impl SensorCheckConfig<f32> {
    /// The constants for the machine model `machine` (the drive's, not the plant's),
    /// control period `control_period` (s) and current limit `current_limit` (A peak).
    pub fn new(
        machine: &MachineParams,
        control_period: f32,
        current_limit: f32,
    ) -> Result<Self, SensorCheckError> {
        let ts = control_period;
        if !(ts.is_finite() && ts > 0.0) {
            return Err(SensorCheckError::ControlPeriod);
        }
        if !(current_limit.is_finite() && current_limit > 0.0) {
            return Err(SensorCheckError::CurrentLimit);
        }
        let sigma_ls = machine.transient_inductance();
        let l_m = machine.magnetizing_inductance();
        if !(sigma_ls.is_finite() && sigma_ls > 0.0 && l_m.is_finite() && l_m > 0.0) {
            return Err(SensorCheckError::Inductance);
        }
        let periods = WINDOW_TIME / ts + 0.5;
        let window = if periods >= MAX_WINDOW as f32 {
            MAX_WINDOW
        } else if periods <= MIN_WINDOW as f32 {
            MIN_WINDOW
        } else {
            periods as u32
        };
        let bias_gain = ts / BIAS_TIME;
        Ok(Self {
            ts_over_sigma_ls: ts / sigma_ls,
            r_sigma: machine.stator_resistance() + machine.referred_rotor_resistance(),
            sigma_ls,
            rr_over_lm: machine.referred_rotor_resistance() / l_m,
            window,
            change_threshold: CHANGE_FRACTION * current_limit,
            response_ratio: RESPONSE_RATIO,
            bias_gain: if bias_gain < 1.0 { bias_gain } else { 1.0 },
            resistance_allowance: RESISTANCE_UNCERTAINTY
                * (machine.stator_resistance() + machine.referred_rotor_resistance())
                * ts
                / sigma_ls,
        })
    }
}

/// What the check needs each period, all at the present sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorCheckInputs<N: Num = f32> {
    /// The phase currents as the drive reads them (offsets removed), A; with two shunts
    /// the third is the derived one (not judged).
    pub phase_currents: [N; 3],
    /// Whether all three channels are measured (three shunts); otherwise a and b.
    pub three_channels: bool,
    /// The same currents in the drive's frame at this sample (Park with `angle`), A.
    pub current: Dq<N>,
    /// The voltage applied over the period that ended at this sample (after the
    /// modulator's limit), in the same frame, V.
    pub voltage: Dq<N>,
    /// Stator (frame) frequency w_s, rad/s electrical.
    pub stator_frequency: N,
    /// Rotor speed estimate p Omega_hat, rad/s electrical.
    pub rotor_speed: N,
    /// Rotor-flux estimate lambda_r (referred, on the d axis), Wb.
    pub rotor_flux: N,
    /// sin/cos of the frame angle at this sample.
    pub angle: SinCosValue<N>,
    /// The gates were on over the whole period that ended at this sample (false also for a
    /// period whose duties the modulator clamped to a pulse-free state on every phase).
    pub switching: bool,
}

/// The check's state: the previous sample, the bias and the running window.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct SensorCheck<N: Num = f32> {
    /// A previous switching sample exists (`previous` is valid).
    primed: bool,
    previous: Dq<N>,
    bias: Dq<N>,
    /// Periods in the running window.
    count: u32,
    start_current: Dq<N>,
    start_phases: [N; 3],
    /// Sum of the bias-corrected predicted increments over the window, A.
    predicted: Dq<N>,
    /// The measured current, low-pass filtered like the bias, A.
    filtered: Dq<N>,
    /// Sum over the window of |i - filtered| (d and q added), A.
    unfollowed: N,
}

impl<N: Num> SensorCheck<N> {
    /// A check with no history.
    pub fn new() -> Self {
        Self::default()
    }

    /// Forgets the history (the next switching sample starts a window); keeps the bias.
    pub fn restart(&mut self) {
        self.primed = false;
        self.count = 0;
        self.predicted = Dq::default();
        self.unfollowed = N::ZERO;
    }

    /// The model's steady error per period (the bias filter), A, for telemetry.
    pub fn bias(&self) -> Dq<N> {
        self.bias
    }

    fn start_window(&mut self, inp: &SensorCheckInputs<N>) {
        self.count = 0;
        self.predicted = Dq::default();
        self.unfollowed = N::ZERO;
        self.start_current = inp.current;
        self.start_phases = inp.phase_currents;
    }

    /// One period: `Some(FaultReason::CurrentSensor)` when a measured channel did not
    /// follow the predicted current over the window that ends here, `None` otherwise
    /// (also while the gates are off, which restarts the window, and for a non-finite
    /// input, which is the supervisor's to report).
    pub fn update(
        &mut self,
        cfg: &SensorCheckConfig<N>,
        inp: &SensorCheckInputs<N>,
    ) -> Option<FaultReason> {
        let finite = inp.phase_currents.iter().all(|x| x.is_finite())
            && inp.current.d.is_finite()
            && inp.current.q.is_finite()
            && inp.voltage.d.is_finite()
            && inp.voltage.q.is_finite()
            && inp.stator_frequency.is_finite()
            && inp.rotor_speed.is_finite()
            && inp.rotor_flux.is_finite();
        if !inp.switching || !finite {
            self.restart();
            return None;
        }
        if !self.primed {
            self.primed = true;
            self.previous = inp.current;
            if self.filtered == Dq::default() {
                self.filtered = inp.current;
            }
            self.start_window(inp);
            return None;
        }
        let i0 = self.previous;
        // sigma Ls di/dt from the previous sample's current and this period's voltage
        let drive_d = inp.voltage.d - N::gain(cfg.r_sigma, i0.d)
            + N::gain_mul(cfg.sigma_ls, inp.stator_frequency, i0.q)
            + N::gain(cfg.rr_over_lm, inp.rotor_flux);
        let drive_q = inp.voltage.q
            - N::gain(cfg.r_sigma, i0.q)
            - N::gain_mul(cfg.sigma_ls, inp.stator_frequency, i0.d)
            - inp.rotor_speed * inp.rotor_flux;
        let delta = Dq {
            d: N::gain(cfg.ts_over_sigma_ls, drive_d),
            q: N::gain(cfg.ts_over_sigma_ls, drive_q),
        };
        let eps_d = (inp.current.d - i0.d) - delta.d;
        let eps_q = (inp.current.q - i0.q) - delta.q;
        self.bias.d = self.bias.d + N::gain(cfg.bias_gain, eps_d - self.bias.d);
        self.bias.q = self.bias.q + N::gain(cfg.bias_gain, eps_q - self.bias.q);
        self.predicted.d = self.predicted.d + delta.d + self.bias.d;
        self.predicted.q = self.predicted.q + delta.q + self.bias.q;
        self.unfollowed =
            self.unfollowed + (i0.d - self.filtered.d).abs() + (i0.q - self.filtered.q).abs();
        self.filtered.d = self.filtered.d + N::gain(cfg.bias_gain, inp.current.d - self.filtered.d);
        self.filtered.q = self.filtered.q + N::gain(cfg.bias_gain, inp.current.q - self.filtered.q);
        self.previous = inp.current;
        self.count = self.count.saturating_add(1);
        if self.count < cfg.window {
            return None;
        }
        // the window's end: the prediction as phase currents
        let end = Dq {
            d: self.start_current.d + self.predicted.d,
            q: self.start_current.q + self.predicted.q,
        };
        let phases = inverse_clarke(inverse_park(end, inp.angle));
        let judged = if inp.three_channels { 3 } else { 2 };
        let allowance = N::gain(cfg.resistance_allowance, self.unfollowed);
        let mut fault = None;
        for ((&p, &start), &meas) in phases
            .iter()
            .zip(self.start_phases.iter())
            .zip(inp.phase_currents.iter())
            .take(judged)
        {
            let change = (p - start).abs();
            let residual = (meas - p).abs();
            if change > cfg.change_threshold
                && residual > N::gain(cfg.response_ratio, change) + allowance
            {
                fault = Some(FaultReason::CurrentSensor);
            }
        }
        self.start_window(inp);
        fault
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::frames::{clarke_three, clarke_two, park, AlphaBeta};
    use std::vec::Vec;

    const TS: f32 = 200e-6;
    const P: f32 = 2.0;

    /// What goes wrong with the current channels, from `at` periods on.
    #[derive(Clone, Copy, Debug, PartialEq)]
    enum Fault {
        None,
        /// Every channel reads 0 A.
        Dead,
        /// Channel `ch` holds its last reading.
        Stuck(usize),
    }

    /// A synthetic drive: the machine's stator and rotor-flux equations in the flux frame
    /// (the controller's frame is the true one), integrated in 10 sub-steps per period,
    /// under dq current PIs (2 pi 200 rad/s, with decoupling and back-EMF feedforward)
    /// whose voltage acts one period later, limited to Vdc/sqrt3 with Vdc = 325 V.
    struct Synth {
        /// The true machine (may differ from the check's model).
        plant: MachineParams,
        /// The controller's and the check's model.
        model: MachineParams,
        i: Dq,
        lambda: f32,
        theta: f32,
        w_r: f32,
        v_next: Dq,
        integ: Dq,
        stuck: [f32; 3],
        last_read: [f32; 3],
        /// Added to the speed the check and the controller see, rad/s electrical.
        speed_error: f32,
    }

    impl Synth {
        fn new(rpm: f32, plant: MachineParams) -> Self {
            let model = MachineParams::paper_table1();
            let w_r = P * rpm * core::f32::consts::PI / 30.0;
            let i_d = Self::flux_current(w_r, &model);
            Self {
                plant,
                model,
                i: Dq { d: i_d, q: 0.0 },
                lambda: plant.magnetizing_inductance() * i_d,
                theta: 0.0,
                w_r,
                v_next: Dq::default(),
                integ: Dq::default(),
                stuck: [0.0; 3],
                last_read: [0.0; 3],
                speed_error: 0.0,
            }
        }

        /// The flux current, weakened so that the back-EMF stays under 150 V.
        fn flux_current(w_r: f32, m: &MachineParams) -> f32 {
            let full: f32 = 1.5;
            let limit = 150.0 / (w_r.abs() * m.magnetizing_inductance()).max(1e-3);
            full.min(limit)
        }

        fn slip(&self, m: &MachineParams, i_q: f32, lambda: f32) -> f32 {
            m.referred_rotor_resistance() * i_q / lambda.max(0.05)
        }

        /// One period: integrate the plant under the voltage computed last period, read the
        /// channels (with `fault`), run the controller for the next period and return the
        /// check's inputs.
        fn period(&mut self, i_q_ref: f32, fault: Fault, three: bool) -> SensorCheckInputs {
            let v = self.v_next;
            let pl = self.plant;
            let (sls, rsig, rr, lm) = (
                pl.transient_inductance(),
                pl.stator_resistance() + pl.referred_rotor_resistance(),
                pl.referred_rotor_resistance(),
                pl.magnetizing_inductance(),
            );
            let h = TS / 10.0;
            let mut w_s = 0.0;
            for _ in 0..10 {
                w_s = self.w_r + self.slip(&pl, self.i.q, self.lambda);
                let did =
                    (v.d - rsig * self.i.d + sls * w_s * self.i.q + rr / lm * self.lambda) / sls;
                let diq =
                    (v.q - rsig * self.i.q - sls * w_s * self.i.d - self.w_r * self.lambda) / sls;
                let dl = rr * self.i.d - rr / lm * self.lambda;
                self.i.d += h * did;
                self.i.q += h * diq;
                self.lambda += h * dl;
                self.theta += h * w_s;
            }
            let sc = SinCosValue {
                sin: libm_free::sin(self.theta),
                cos: libm_free::cos(self.theta),
            };
            let truth = inverse_clarke(inverse_park(self.i, sc));
            let mut read = truth;
            match fault {
                Fault::None => {}
                Fault::Dead => read = [0.0; 3],
                Fault::Stuck(ch) => {
                    if self.stuck == [0.0; 3] {
                        self.stuck = self.last_read;
                    }
                    read[ch] = self.stuck[ch];
                }
            }
            if !three {
                read[2] = -read[0] - read[1];
            }
            self.last_read = read;
            let ab: AlphaBeta = if three {
                clarke_three(read[0], read[1], read[2])
            } else {
                clarke_two(read[0], read[1])
            };
            let meas = park(ab, sc);
            // the controller, on the measurements and the model (with a speed error)
            let m = self.model;
            let w_hat = self.w_r + self.speed_error;
            let lambda_hat = self.lambda;
            let w_s_hat = w_hat + self.slip(&m, meas.q, lambda_hat);
            let wc = 2.0 * core::f32::consts::PI * 200.0;
            let (kp, ki) = (
                wc * m.transient_inductance(),
                wc * (m.stator_resistance() + m.referred_rotor_resistance()),
            );
            let i_d_ref = Self::flux_current(self.w_r, &m);
            let e = Dq {
                d: i_d_ref - meas.d,
                q: i_q_ref - meas.q,
            };
            self.integ.d += ki * TS * e.d;
            self.integ.q += ki * TS * e.q;
            let ff = Dq {
                d: -m.transient_inductance() * w_s_hat * meas.q
                    - m.referred_rotor_resistance() / m.magnetizing_inductance() * lambda_hat,
                q: m.transient_inductance() * w_s_hat * meas.d + w_hat * lambda_hat,
            };
            let mut vn = Dq {
                d: kp * e.d + self.integ.d + ff.d,
                q: kp * e.q + self.integ.q + ff.q,
            };
            let vmax = 325.0 / 1.732;
            let mag = (vn.d * vn.d + vn.q * vn.q).sqrt();
            if mag > vmax {
                vn.d *= vmax / mag;
                vn.q *= vmax / mag;
                // anti-windup: hold the integrators
                self.integ.d -= ki * TS * e.d;
                self.integ.q -= ki * TS * e.q;
            }
            self.v_next = vn;
            let _ = w_s;
            SensorCheckInputs {
                phase_currents: read,
                three_channels: three,
                current: meas,
                voltage: v,
                stator_frequency: w_s_hat,
                rotor_speed: w_hat,
                rotor_flux: lambda_hat,
                angle: sc,
                switching: true,
            }
        }

        fn peak(&self) -> f32 {
            (self.i.d * self.i.d + self.i.q * self.i.q).sqrt()
        }
    }

    /// sin and cos by range reduction and Taylor series (tests only; the crate has no
    /// libm).
    mod libm_free {
        pub fn sin(x: f32) -> f32 {
            cos(x - core::f32::consts::FRAC_PI_2)
        }
        pub fn cos(x: f32) -> f32 {
            let x = crate::math::wrap_angle(x);
            let x2 = x * x;
            let mut term = 1.0f32;
            let mut sum = 1.0f32;
            for k in 1..10 {
                term *= -x2 / ((2 * k - 1) * (2 * k)) as f32;
                sum += term;
            }
            sum
        }
    }

    fn cfg() -> SensorCheckConfig {
        SensorCheckConfig::new(&MachineParams::paper_table1(), TS, 4.67).unwrap()
    }

    /// Runs `settle` healthy periods, then `n` periods with `fault` from the first;
    /// `i_q` gives the q-current reference per period. Returns the period (counted from
    /// the failure) the check reported in, and the largest true current magnitude.
    fn run(
        s: &mut Synth,
        fault: Fault,
        three: bool,
        settle: usize,
        n: usize,
        i_q: &dyn Fn(usize) -> f32,
    ) -> (Option<usize>, f32) {
        let cfg = cfg();
        let mut check = SensorCheck::new();
        for k in 0..settle {
            let inp = s.period(i_q(k), Fault::None, three);
            assert_eq!(check.update(&cfg, &inp), None, "healthy, period {k}");
        }
        let mut peak = 0.0f32;
        for k in 0..n {
            let inp = s.period(i_q(settle + k), fault, three);
            peak = peak.max(s.peak());
            if let Some(r) = check.update(&cfg, &inp) {
                assert_eq!(r, FaultReason::CurrentSensor);
                return (Some(k), peak);
            }
        }
        (None, peak)
    }

    const SPEEDS: [f32; 4] = [0.0, 60.0, 500.0, 1500.0];

    #[test]
    fn the_configuration_follows_the_design() {
        let c = cfg();
        assert_eq!(c.window, 8);
        assert!((c.change_threshold - 0.7005).abs() < 1e-3);
        assert!(
            (c.ts_over_sigma_ls - TS / MachineParams::paper_table1().transient_inductance()).abs()
                < 1e-9
        );
        let m = MachineParams::paper_table1();
        assert_eq!(
            SensorCheckConfig::new(&m, 0.0, 4.67),
            Err(SensorCheckError::ControlPeriod)
        );
        assert_eq!(
            SensorCheckConfig::new(&m, f32::NAN, 4.67),
            Err(SensorCheckError::ControlPeriod)
        );
        assert_eq!(
            SensorCheckConfig::new(&m, TS, -1.0),
            Err(SensorCheckError::CurrentLimit)
        );
        assert_eq!(
            SensorCheckConfig::new(&m, 1e-6, 4.67).unwrap().window,
            MAX_WINDOW
        );
        assert_eq!(
            SensorCheckConfig::new(&m, 1e-3, 4.67).unwrap().window,
            MIN_WINDOW
        );
    }

    /// Healthy channels at standstill, 60, 500 and 1500 rpm (flux weakened there), with
    /// no load, a load-current step to the limit and back, and a current reversal: no
    /// report over 0.4 s, two and three shunts.
    #[test]
    fn healthy_channels_through_load_steps_are_never_reported() {
        let steps = |k: usize| match k / 500 {
            0 => 0.0,
            1 => 4.0,
            2 => -4.0,
            _ => 1.0,
        };
        for rpm in SPEEDS {
            for three in [false, true] {
                let mut s = Synth::new(rpm, MachineParams::paper_table1());
                let (hit, _) = run(&mut s, Fault::None, three, 200, 2000, &steps);
                assert_eq!(hit, None, "{rpm} rpm, three {three}");
            }
        }
    }

    /// Healthy channels with the model wrong: plant Rs +50 %, R_R +30 %, sigma Ls -20 %
    /// and +20 %, a 30 rpm speed-estimate error; load steps as above: no report.
    #[test]
    fn model_errors_are_not_sensor_faults() {
        let base = MachineParams::paper_table1().data();
        let mut cases = Vec::new();
        for (rs, rr, l) in [
            (1.5, 1.0, 1.0),
            (1.0, 1.3, 1.0),
            (1.0, 1.0, 0.8),
            (1.0, 1.0, 1.2),
            (1.5, 1.3, 0.8),
        ] {
            let mut d = base;
            d.stator_resistance *= rs;
            d.rotor_resistance *= rr;
            // leakage scaled: Ls and Lr move together around Lm
            let leak_s = d.stator_inductance - d.mutual_inductance;
            let leak_r = d.rotor_inductance - d.mutual_inductance;
            d.stator_inductance = d.mutual_inductance + l * leak_s;
            d.rotor_inductance = d.mutual_inductance + l * leak_r;
            cases.push(MachineParams::new(d).unwrap());
        }
        let steps = |k: usize| if (k / 400) % 2 == 1 { 4.0 } else { 1.0 };
        for plant in cases {
            for rpm in SPEEDS {
                for err_rpm in [0.0, 30.0] {
                    let mut s = Synth::new(rpm, plant);
                    s.speed_error = P * err_rpm * core::f32::consts::PI / 30.0;
                    let (hit, _) = run(&mut s, Fault::None, false, 200, 2000, &steps);
                    assert_eq!(hit, None, "{rpm} rpm, speed error {err_rpm} rpm, {plant:?}");
                }
            }
        }
    }

    /// Every channel at 0 A, loaded (2 A of torque current) or not, at every speed: reported
    /// within two windows.
    #[test]
    fn dead_channels_are_reported_within_two_windows() {
        let bound = 2 * cfg().window as usize;
        for rpm in SPEEDS {
            for i_q in [0.0, 2.0] {
                for three in [false, true] {
                    let mut s = Synth::new(rpm, MachineParams::paper_table1());
                    let (hit, peak) = run(&mut s, Fault::Dead, three, 300, 200, &|_| i_q);
                    let k = hit.unwrap_or_else(|| panic!("{rpm} rpm, i_q {i_q}: not found"));
                    std::println!("dead, {rpm} rpm, i_q {i_q}, three {three}: {k} periods");
                    assert!(
                        k < bound,
                        "{rpm} rpm, i_q {i_q}: after {k} periods (peak {peak} A)"
                    );
                }
            }
        }
    }

    /// One channel stuck at its last reading, loaded, at every speed but standstill
    /// (two shunts: a or b; three shunts: any): reported within 200 periods (40 ms),
    /// before the true current leaves the current limit (the periods it took are printed
    /// with `--nocapture`; the module documentation quotes them).
    #[test]
    fn stuck_channels_are_reported() {
        for rpm in [60.0, 500.0, 1500.0] {
            for (three, ch) in [(false, 0), (false, 1), (true, 0), (true, 1), (true, 2)] {
                let mut s = Synth::new(rpm, MachineParams::paper_table1());
                let (hit, peak) = run(&mut s, Fault::Stuck(ch), three, 300, 2000, &|_| 2.0);
                let k =
                    hit.unwrap_or_else(|| panic!("{rpm} rpm, ch {ch}, three {three}: not found"));
                std::println!("{rpm} rpm ch {ch} three {three}: {k} periods, peak {peak}");
                assert!(k < 200, "{rpm} rpm, ch {ch}: after {k} periods");
                assert!(
                    peak < 4.67,
                    "{rpm} rpm, ch {ch}: true current {peak} A before the report"
                );
            }
        }
    }

    /// Gates off (and back on): no judgement across the gap.
    #[test]
    fn gates_off_restart_the_window() {
        let cfg = cfg();
        let mut s = Synth::new(500.0, MachineParams::paper_table1());
        let mut check = SensorCheck::new();
        for k in 0..100 {
            let mut inp = s.period(1.0, Fault::None, false);
            if k % 7 == 3 {
                inp.switching = false;
            }
            assert_eq!(check.update(&cfg, &inp), None);
        }
        let mut inp = s.period(1.0, Fault::None, false);
        inp.voltage.d = f32::NAN;
        assert_eq!(check.update(&cfg, &inp), None);
    }
}
