//! Fault injection: the hardware failures a drive must detect, applied to the plant at
//! given times so that scenarios and tests share one definition of each fault.

use crate::{DcLink, Measurements, Plant};
use acim::PwmOutput;

/// When each fault starts, s from the start of the run (`None`: never).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct FaultPlan {
    /// Mains sag: the DC-link source drops to [`FaultPlan::bus_sag_to_v`].
    pub bus_sag_at_s: Option<f32>,
    /// Source voltage after the sag, V.
    pub bus_sag_to_v: f32,
    /// The rotor locks (speed held at zero).
    pub locked_rotor_at_s: Option<f32>,
    /// Phase a's low-side switch fails short: phase a is held at DC- while the gates are
    /// enabled.
    pub phase_short_at_s: Option<f32>,
    /// One phase-current sample (phase a) reads NaN (a corrupted ADC transfer).
    pub nan_sample_at_s: Option<f32>,
    /// A motor phase opens (cable or contactor): phase [`FaultPlan::open_phase`] carries
    /// no current from then on.
    pub open_phase_at_s: Option<f32>,
    /// The phase that opens, 0..=2 (a, b, c).
    pub open_phase: usize,
    /// One current channel sticks (amplifier or ADC input stuck).
    pub current_sensor_stuck_at_s: Option<f32>,
    /// The stuck channel, 0..=2.
    pub current_sensor_stuck_channel: usize,
    /// The value it reads, A (`None`: the last value before the fault).
    pub current_sensor_stuck_value_a: Option<f32>,
    /// Every current channel reads its zero-current code (sense cable off, amplifiers at
    /// their bias).
    pub current_sensors_zero_at_s: Option<f32>,
    /// Offset drift of channel a from the start, A/s (thermal drift of the amplifier).
    pub current_sensor_offset_drift_a_per_s: f32,
    /// Offsets added to the three current channels after the start's offset measurement,
    /// A: zero until [`FaultPlan::current_sensor_offset_change_at_s`], then reached
    /// linearly over [`FaultPlan::current_sensor_offset_change_ramp_s`] and held (an
    /// amplifier's drift while the motor runs).
    pub current_sensor_offset_change_a: [f32; 3],
    /// When the offset change starts, s (`None`: never).
    pub current_sensor_offset_change_at_s: Option<f32>,
    /// How long the offset change takes to reach its value, s (0: a step).
    pub current_sensor_offset_change_ramp_s: f32,
}

/// Applies a [`FaultPlan`] to a plant, its DC link, its samples and its inverter command.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct FaultInjector {
    plan: FaultPlan,
    short_active: bool,
    nan_done: bool,
    /// The samples of the last period (the value a channel sticks at by default).
    last_sample: [f32; 3],
    /// The value the stuck channel reads, once stuck.
    stuck_value: Option<f32>,
}

impl FaultInjector {
    /// An injector for `plan`, nothing injected yet.
    pub fn new(plan: FaultPlan) -> Self {
        Self {
            plan,
            short_active: false,
            nan_done: false,
            last_sample: [0.0; 3],
            stuck_value: None,
        }
    }

    /// The plan.
    pub fn plan(&self) -> &FaultPlan {
        &self.plan
    }

    /// At the start of the period beginning at `t` (s): applies the faults that are due
    /// to the plant and the DC link.
    pub fn begin_period(&mut self, t: f32, plant: &mut Plant, dc_link: &mut DcLink) {
        let p = &self.plan;
        if p.bus_sag_at_s.is_some_and(|ta| t >= ta) {
            dc_link.set_source_voltage(p.bus_sag_to_v);
        }
        if p.locked_rotor_at_s.is_some_and(|ta| t >= ta) && !plant.machine().is_locked() {
            plant.machine_mut().set_locked(true);
        }
        self.short_active = self.short_active || p.phase_short_at_s.is_some_and(|ta| t >= ta);
        if p.open_phase_at_s.is_some_and(|ta| t >= ta) {
            plant.set_open_phase(Some(p.open_phase));
        }
    }

    /// Corrupts the sample taken at `t` (s) as the plan says: offset drift, a stuck
    /// channel, all channels at zero, one NaN.
    pub fn corrupt_sample(&mut self, t: f32, m: &mut Measurements) {
        let p = &self.plan;
        if p.current_sensor_offset_drift_a_per_s != 0.0 {
            m.phase_currents[0] += p.current_sensor_offset_drift_a_per_s * t;
        }
        if let Some(t0) = p.current_sensor_offset_change_at_s.filter(|&t0| t >= t0) {
            let ramp = p.current_sensor_offset_change_ramp_s;
            let k = if t - t0 >= ramp { 1.0 } else { (t - t0) / ramp };
            for (i, o) in m
                .phase_currents
                .iter_mut()
                .zip(p.current_sensor_offset_change_a)
            {
                *i += k * o;
            }
        }
        if p.current_sensor_stuck_at_s.is_some_and(|ta| t >= ta) {
            let ch = p.current_sensor_stuck_channel.min(2);
            let v = match self.stuck_value {
                Some(v) => v,
                None => p
                    .current_sensor_stuck_value_a
                    .unwrap_or(self.last_sample[ch]),
            };
            self.stuck_value = Some(v);
            m.phase_currents[ch] = v;
        }
        if p.current_sensors_zero_at_s.is_some_and(|ta| t >= ta) {
            m.phase_currents = [0.0; 3];
        }
        if !self.nan_done && p.nan_sample_at_s.is_some_and(|ta| t >= ta) {
            m.phase_currents[0] = f32::NAN;
            self.nan_done = true;
        }
        self.last_sample = m.phase_currents;
    }

    /// What the inverter really applies for the command `applied`: with a shorted
    /// low-side switch, phase a sits at DC- whenever the gates are enabled.
    pub fn inverter_command(&self, applied: PwmOutput) -> PwmOutput {
        let mut out = applied;
        if self.short_active && out.enabled {
            out.duties[0] = 0.0;
        }
        out
    }

    /// Whether the phase short has happened.
    pub fn phase_short_active(&self) -> bool {
        self.short_active
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use acim::MachineParams;

    #[test]
    fn faults_start_at_their_time() {
        let plan = FaultPlan {
            bus_sag_at_s: Some(1.0),
            bus_sag_to_v: 150.0,
            locked_rotor_at_s: Some(2.0),
            phase_short_at_s: Some(3.0),
            nan_sample_at_s: Some(4.0),
            ..FaultPlan::default()
        };
        let mut f = FaultInjector::new(plan);
        let mut plant = Plant::ideal(MachineParams::paper_table1(), 325.0);
        let mut link = DcLink::stiff(325.0);
        let on = PwmOutput {
            duties: [0.7; 3],
            enabled: true,
        };
        f.begin_period(0.5, &mut plant, &mut link);
        assert_eq!(link.source_voltage(), 325.0);
        assert_eq!(f.inverter_command(on), on);
        f.begin_period(2.5, &mut plant, &mut link);
        assert_eq!(link.source_voltage(), 150.0);
        assert!(plant.machine().is_locked());
        assert_eq!(f.inverter_command(on), on);
        f.begin_period(3.0, &mut plant, &mut link);
        assert_eq!(f.inverter_command(on).duties, [0.0, 0.7, 0.7]);
        assert_eq!(f.inverter_command(PwmOutput::OFF), PwmOutput::OFF);
        let mut m = plant.sample();
        f.corrupt_sample(3.9, &mut m);
        assert!(m.phase_currents[0].is_finite());
        f.corrupt_sample(4.0, &mut m);
        assert!(m.phase_currents[0].is_nan());
        let mut m = plant.sample();
        f.corrupt_sample(4.2, &mut m);
        assert!(m.phase_currents[0].is_finite(), "one NaN sample only");
    }

    #[test]
    fn sensor_faults_corrupt_the_samples() {
        let plan = FaultPlan {
            current_sensor_stuck_at_s: Some(1.0),
            current_sensor_stuck_channel: 1,
            current_sensors_zero_at_s: Some(2.0),
            current_sensor_offset_drift_a_per_s: 0.5,
            ..FaultPlan::default()
        };
        let mut f = FaultInjector::new(plan);
        let mut m = Measurements {
            phase_currents: [1.0, 2.0, -3.0],
            dc_bus: 300.0,
            channels: crate::CurrentChannels::Three,
        };
        f.corrupt_sample(0.5, &mut m);
        assert_eq!(m.phase_currents, [1.25, 2.0, -3.0]);
        // stuck at the last value of channel 1
        let mut m2 = m;
        m2.phase_currents = [0.0, 7.0, -7.0];
        f.corrupt_sample(1.0, &mut m2);
        assert_eq!(m2.phase_currents, [0.5, 2.0, -7.0]);
        m2.phase_currents = [0.0, 9.0, -9.0];
        f.corrupt_sample(1.5, &mut m2);
        assert_eq!(m2.phase_currents[1], 2.0);
        f.corrupt_sample(2.0, &mut m2);
        assert_eq!(m2.phase_currents, [0.0; 3]);
    }
}
