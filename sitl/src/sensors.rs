//! The vehicle's own sensors (besides the camera): a downward sonar, the flight controller's IMU
//! yaw with the occasional spike the thesis saw (000 §5.3), and the battery voltage.

use crate::rng::Rng;
use crate::vehicle::Vehicle;

/// Sensor characteristics.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorParams {
    /// Sonar range, metres (no echo beyond).
    pub sonar_max: f64,
    /// Height of the sonar above the floor when landed, metres.
    pub sonar_mount: f64,
    /// Sonar noise, metres (1 σ).
    pub sonar_sigma: f64,
    /// IMU yaw noise, radians (1 σ).
    pub yaw_sigma: f64,
    /// Probability that one IMU yaw sample is a spike.
    pub yaw_spike_probability: f64,
    /// Largest spike, radians.
    pub yaw_spike_max: f64,
    /// Battery voltage noise, V (1 σ).
    pub battery_sigma: f64,
}

impl Default for SensorParams {
    fn default() -> Self {
        Self {
            sonar_max: 4.0,
            sonar_mount: 0.03,
            sonar_sigma: 0.005,
            yaw_sigma: 0.3f64.to_radians(),
            yaw_spike_probability: 0.002,
            yaw_spike_max: 90f64.to_radians(),
            battery_sigma: 0.01,
        }
    }
}

/// One sample of every sensor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Readings {
    /// Sonar distance to the floor, metres; `None` without an echo.
    pub sonar: Option<f64>,
    /// IMU yaw, radians (map frame, anticlockwise), spikes included.
    pub yaw: f64,
    /// Battery voltage, V.
    pub battery_v: f64,
    /// Battery left, percent.
    pub battery_pct: u8,
}

/// A vehicle's sensors with their own noise stream.
#[derive(Debug, Clone)]
pub struct Sensors {
    params: SensorParams,
    rng: Rng,
}

impl Sensors {
    /// Sensors with noise from `rng`.
    pub fn new(params: SensorParams, rng: Rng) -> Self {
        Self { params, rng }
    }

    /// Samples every sensor on `vehicle` now.
    pub fn sample(&mut self, vehicle: &Vehicle) -> Readings {
        let p = &self.params;
        let s = vehicle.state();
        // The sonar points down the body's z axis: tilt lengthens the path to the floor.
        let tilt = (s.roll.cos() * s.pitch.cos()).max(0.2);
        let range = (s.position[2] + p.sonar_mount) / tilt + p.sonar_sigma * self.rng.normal();
        let sonar = (range <= p.sonar_max).then_some(range.max(0.0));
        let mut yaw = s.yaw + p.yaw_sigma * self.rng.normal();
        if self.rng.chance(p.yaw_spike_probability) {
            yaw += (2.0 * self.rng.uniform() - 1.0) * p.yaw_spike_max;
        }
        Readings {
            sonar,
            yaw: crate::vehicle::wrap(yaw),
            battery_v: vehicle.battery_voltage() + p.battery_sigma * self.rng.normal(),
            battery_pct: vehicle.battery_remaining(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vehicle::VehicleParams;

    #[test]
    fn sonar_reads_height_and_yaw_spikes_now_and_then() {
        let v = Vehicle::new(VehicleParams::default(), 1.0, 1.0, 0.5);
        let mut s = Sensors::new(SensorParams::default(), Rng::new(1, 1));
        let samples: Vec<Readings> = (0..20_000).map(|_| s.sample(&v)).collect();
        let sonar_mean = samples
            .iter()
            .map(|r| r.sonar.unwrap_or(f64::NAN))
            .sum::<f64>()
            / 20_000.0;
        assert!((sonar_mean - 0.03).abs() < 0.001, "{sonar_mean}");
        let spikes = samples
            .iter()
            .filter(|r| (r.yaw - 0.5).abs() > 5f64.to_radians())
            .count();
        // p = 0.002, and a spike is at least 5° in 94 % of cases: about 38 of 20 000.
        assert!((15..=70).contains(&spikes), "{spikes} spikes");
        assert!(samples.iter().all(|r| (r.battery_v - 12.6).abs() < 0.1));
    }

    #[test]
    fn no_echo_beyond_range() {
        let params = SensorParams {
            sonar_max: 0.01,
            ..SensorParams::default()
        };
        let v = Vehicle::new(VehicleParams::default(), 1.0, 1.0, 0.0);
        let mut s = Sensors::new(params, Rng::new(1, 1));
        assert_eq!(s.sample(&v).sonar, None);
    }
}
