//! Stick commands and how a vehicle's wiring turns them into RC pulse widths.
//!
//! Inside the station sticks are unitless in [-1, 1]; pulse widths in µs exist only here, at the
//! link boundary. Each vehicle has a [`ChannelMap`]: which RC channel carries each axis, whether
//! the axis is reversed, the pulse range, and the dead zone round mid stick (ArduPilot's
//! `RCn_MIN`, `RCn_MAX`, `RCn_REVERSED`, `RCn_DZ`).
//!
//! A flight controller ignores pulses within its dead zone of mid stick and scales the rest from
//! the zone's edge. A position controller's small corrections would be lost in it (with 20 µs of
//! 400, an error under 0.17 m at a gain of 0.3 asks for nothing, and the drone holds wherever it
//! drifted to), so [`ChannelMap::pulses`] sends any non-zero stick from just past the dead zone,
//! and [`ChannelMap::sticks`], the flight controller's side, takes it back out: the two are
//! inverse, and the stick the station commands is the stick the vehicle flies.

/// The four stick axes, in the order the shield protocol sends them (roll, pitch, yaw, throttle).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Axis {
    /// Bank: +1 = bank right.
    Roll,
    /// Nose: +1 = nose down, i.e. fly forward.
    Pitch,
    /// Heading: +1 = turn clockwise seen from above (to the right).
    Yaw,
    /// Vertical: +1 = climb at full rate, 0 = hold altitude, -1 = descend at full rate.
    Throttle,
}

impl Axis {
    /// All axes in shield (RPYT) order.
    pub const ALL: [Axis; 4] = [Axis::Roll, Axis::Pitch, Axis::Yaw, Axis::Throttle];
}

/// A stick command; each axis is clamped to [-1, 1] and a non-finite value counts as 0.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sticks {
    /// +1 = bank right.
    pub roll: f32,
    /// +1 = nose down (forward).
    pub pitch: f32,
    /// +1 = yaw clockwise (right).
    pub yaw: f32,
    /// +1 = climb, 0 = hold altitude (mid stick), -1 = descend.
    pub throttle: f32,
}

impl Sticks {
    /// Centred sticks: level, no turn, hold altitude.
    pub const CENTRED: Sticks = Sticks {
        roll: 0.0,
        pitch: 0.0,
        yaw: 0.0,
        throttle: 0.0,
    };

    /// The value of one axis, clamped to [-1, 1].
    pub fn get(&self, axis: Axis) -> f32 {
        let v = match axis {
            Axis::Roll => self.roll,
            Axis::Pitch => self.pitch,
            Axis::Yaw => self.yaw,
            Axis::Throttle => self.throttle,
        };
        if v.is_finite() {
            v.clamp(-1.0, 1.0)
        } else {
            0.0
        }
    }

    fn set(&mut self, axis: Axis, v: f32) {
        match axis {
            Axis::Roll => self.roll = v,
            Axis::Pitch => self.pitch = v,
            Axis::Yaw => self.yaw = v,
            Axis::Throttle => self.throttle = v,
        }
    }
}

/// Pulse widths in µs for the four axes, in RPYT order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Pulses {
    /// Roll channel pulse.
    pub roll: u16,
    /// Pitch channel pulse.
    pub pitch: u16,
    /// Yaw channel pulse.
    pub yaw: u16,
    /// Throttle channel pulse.
    pub throttle: u16,
}

impl Pulses {
    /// The pulse of one axis.
    pub fn get(&self, axis: Axis) -> u16 {
        match axis {
            Axis::Roll => self.roll,
            Axis::Pitch => self.pitch,
            Axis::Yaw => self.yaw,
            Axis::Throttle => self.throttle,
        }
    }

    /// Sets the pulse of one axis.
    pub fn set(&mut self, axis: Axis, us: u16) {
        match axis {
            Axis::Roll => self.roll = us,
            Axis::Pitch => self.pitch = us,
            Axis::Yaw => self.yaw = us,
            Axis::Throttle => self.throttle = us,
        }
    }
}

/// The RC channel carrying one axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Channel {
    /// RC channel number, 1-based (MAVLink `chan1_raw` is 1).
    pub number: u8,
    /// Reversed: +1 on the stick gives the minimum pulse.
    pub reversed: bool,
}

/// A vehicle's RC wiring: channel per axis, reversal, pulse range and dead zone.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChannelMap {
    /// Roll channel.
    pub roll: Channel,
    /// Pitch channel.
    pub pitch: Channel,
    /// Yaw channel.
    pub yaw: Channel,
    /// Throttle channel.
    pub throttle: Channel,
    /// Pulse at -1 (or +1 when reversed), µs.
    pub min_us: u16,
    /// Pulse at +1 (or -1 when reversed), µs.
    pub max_us: u16,
    /// Pulses within this of mid stick read as centred, on every axis, µs.
    pub dead_zone_us: u16,
}

/// A channel map that cannot be used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("bad channel map: {0}")]
pub struct ChannelMapError(pub String);

impl ChannelMap {
    /// ArduPilot Copter defaults (RCMAP 1-2-3-4, 1100–1900 µs, a dead zone of 20 µs). Pitch is
    /// reversed: ArduPilot reads a low pitch pulse as stick forward (nose down).
    pub fn ardupilot() -> Self {
        Self {
            roll: Channel {
                number: 1,
                reversed: false,
            },
            pitch: Channel {
                number: 2,
                reversed: true,
            },
            throttle: Channel {
                number: 3,
                reversed: false,
            },
            yaw: Channel {
                number: 4,
                reversed: false,
            },
            min_us: 1100,
            max_us: 1900,
            dead_zone_us: 20,
        }
    }

    /// The thesis's I/O shield wired to a DJI Naza (1000–2000 µs): every axis reversed, so 2 ms
    /// means roll left, pitch back, no thrust and yaw counter-clockwise. DJI does not publish the
    /// Naza's dead zone; 25 µs (5 % of the half range) is assumed.
    pub fn thesis_naza() -> Self {
        Self {
            roll: Channel {
                number: 1,
                reversed: true,
            },
            pitch: Channel {
                number: 2,
                reversed: true,
            },
            throttle: Channel {
                number: 3,
                reversed: true,
            },
            yaw: Channel {
                number: 4,
                reversed: true,
            },
            min_us: 1000,
            max_us: 2000,
            dead_zone_us: 25,
        }
    }

    /// Checks channel numbers (1–18, distinct), the pulse range (within 800–2200, min < max) and
    /// the dead zone (under a quarter of the half range).
    pub fn validate(&self) -> Result<(), ChannelMapError> {
        let numbers = Axis::ALL.map(|a| self.channel(a).number);
        if let Some(n) = numbers.iter().find(|n| !(1..=18).contains(*n)) {
            return Err(ChannelMapError(format!("channel {n} is outside 1..=18")));
        }
        for (i, n) in numbers.iter().enumerate() {
            if numbers[..i].contains(n) {
                return Err(ChannelMapError(format!("channel {n} is used for two axes")));
            }
        }
        if !(800..=2200).contains(&self.min_us) || !(800..=2200).contains(&self.max_us) {
            return Err(ChannelMapError(
                "pulse range must lie within 800–2200 µs".into(),
            ));
        }
        if self.min_us >= self.max_us {
            return Err(ChannelMapError(format!(
                "min_us {} must be below max_us {}",
                self.min_us, self.max_us
            )));
        }
        if u32::from(self.dead_zone_us) * 8 >= u32::from(self.max_us - self.min_us) {
            return Err(ChannelMapError(format!(
                "dead zone {} µs must be under a quarter of the half range {}–{} µs",
                self.dead_zone_us, self.min_us, self.max_us
            )));
        }
        Ok(())
    }

    /// The channel of one axis.
    pub fn channel(&self, axis: Axis) -> Channel {
        match axis {
            Axis::Roll => self.roll,
            Axis::Pitch => self.pitch,
            Axis::Yaw => self.yaw,
            Axis::Throttle => self.throttle,
        }
    }

    /// The pulse at mid stick.
    pub fn mid_us(&self) -> u16 {
        ((u32::from(self.min_us) + u32::from(self.max_us)) / 2) as u16
    }

    /// Sticks → pulse widths, per axis: 0 is mid stick, any other stick lies past the dead zone
    /// in proportion (±1 at the ends). Always within `min_us..=max_us`.
    pub fn pulses(&self, sticks: &Sticks) -> Pulses {
        let mut p = Pulses {
            roll: 0,
            pitch: 0,
            yaw: 0,
            throttle: 0,
        };
        let (mid, half, zone) = self.geometry();
        let (lo, hi) = (
            f32::from(self.min_us.min(self.max_us)),
            f32::from(self.min_us.max(self.max_us)),
        );
        for axis in Axis::ALL {
            let mut v = sticks.get(axis);
            if self.channel(axis).reversed {
                v = -v;
            }
            let offset = if v == 0.0 {
                0.0
            } else {
                v.signum() * (zone + v.abs() * (half - zone))
            };
            let us = (mid + offset).round().clamp(lo, hi);
            p.set(axis, us as u16);
        }
        p
    }

    /// Pulse widths → sticks, as a flight controller reads them: centred within the dead zone,
    /// scaled from its edge beyond it. Out-of-range pulses saturate.
    pub fn sticks(&self, pulses: &Pulses) -> Sticks {
        let mut s = Sticks::CENTRED;
        let (mid, half, zone) = self.geometry();
        for axis in Axis::ALL {
            let offset = f32::from(pulses.get(axis)) - mid;
            let mut v = (offset.signum() * ((offset.abs() - zone).max(0.0) / (half - zone)))
                .clamp(-1.0, 1.0);
            if self.channel(axis).reversed {
                v = -v;
            }
            s.set(axis, v);
        }
        s
    }

    /// Mid stick, the half range and the dead zone, µs (the zone kept under the half range, so
    /// an unvalidated map divides by no zero).
    fn geometry(&self) -> (f32, f32, f32) {
        let half = f32::from(self.max_us.saturating_sub(self.min_us)).max(2.0) / 2.0;
        let mid = f32::from(self.min_us) + half;
        (mid, half, f32::from(self.dead_zone_us).min(half / 2.0))
    }

    /// Sticks → the 18 RC channels of a MAVLink override: the four mapped channels carry pulses,
    /// every other channel is `u16::MAX` ("leave this channel alone").
    pub fn override_channels(&self, sticks: &Sticks) -> [u16; 18] {
        let mut out = [u16::MAX; 18];
        let p = self.pulses(sticks);
        for axis in Axis::ALL {
            out[usize::from(self.channel(axis).number - 1)] = p.get(axis);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn thesis_wiring_is_reversed_on_every_axis() {
        let m = ChannelMap::thesis_naza();
        // 2 ms = roll left, pitch back, no thrust, yaw counter-clockwise.
        let p = m.pulses(&Sticks {
            roll: -1.0,
            pitch: -1.0,
            yaw: -1.0,
            throttle: -1.0,
        });
        assert_eq!(
            p,
            Pulses {
                roll: 2000,
                pitch: 2000,
                yaw: 2000,
                throttle: 2000
            }
        );
        assert_eq!(
            m.pulses(&Sticks::CENTRED),
            Pulses {
                roll: 1500,
                pitch: 1500,
                yaw: 1500,
                throttle: 1500
            }
        );
    }

    #[test]
    fn ardupilot_pitch_forward_is_a_low_pulse() {
        let m = ChannelMap::ardupilot();
        let ch = m.override_channels(&Sticks {
            pitch: 1.0,
            roll: 0.5,
            ..Sticks::CENTRED
        });
        assert_eq!(ch[1], 1100);
        // Half roll: half of the way from the dead zone's edge (1520 µs) to the end.
        assert_eq!(ch[0], 1710);
        assert_eq!(ch[2], 1500);
        assert_eq!(ch[3], 1500);
        assert!(ch[4..].iter().all(|&c| c == u16::MAX));
    }

    #[test]
    fn bad_maps_are_rejected() {
        let mut m = ChannelMap::ardupilot();
        m.yaw.number = 1;
        assert!(m.validate().unwrap_err().0.contains("two axes"));
        let mut m = ChannelMap::ardupilot();
        m.roll.number = 0;
        assert!(m.validate().is_err());
        let mut m = ChannelMap::ardupilot();
        m.min_us = 1900;
        assert!(m.validate().is_err());
        let mut m = ChannelMap::ardupilot();
        m.dead_zone_us = 100;
        assert!(m.validate().unwrap_err().0.contains("dead zone 100"));
        // An unvalidated map still maps without a panic.
        m.min_us = 1900;
        m.max_us = 1100;
        let _ = m.sticks(&m.pulses(&Sticks::CENTRED));
        assert!(ChannelMap::thesis_naza().validate().is_ok());
    }

    #[test]
    fn small_sticks_go_past_the_dead_zone_and_come_back_unchanged() {
        let m = ChannelMap::ardupilot();
        let small = Sticks {
            roll: 0.01,
            pitch: 0.01,
            yaw: -0.01,
            throttle: 0.0,
        };
        let p = m.pulses(&small);
        // 1500 ± (20 + 0.01 · 380) µs; pitch is reversed.
        assert_eq!(
            (p.roll, p.pitch, p.yaw, p.throttle),
            (1524, 1476, 1476, 1500)
        );
        let back = m.sticks(&p);
        for a in Axis::ALL {
            assert!(
                (back.get(a) - small.get(a)).abs() < 0.002,
                "{a:?}: {back:?}"
            );
        }
        // The flight controller's side: within the dead zone is centred, beyond it is scaled
        // from its edge.
        let read = |us: u16| {
            m.sticks(&Pulses {
                roll: us,
                pitch: 1500,
                yaw: 1500,
                throttle: 1500,
            })
            .roll
        };
        assert_eq!(read(1519), 0.0);
        assert_eq!(read(1481), 0.0);
        assert!((read(1710) - 0.5).abs() < 1e-6);
        assert_eq!(read(1900), 1.0);
        assert_eq!(read(2100), 1.0, "out of range saturates");
    }

    #[test]
    fn non_finite_sticks_centre() {
        let m = ChannelMap::ardupilot();
        let p = m.pulses(&Sticks {
            roll: f32::NAN,
            pitch: f32::INFINITY,
            yaw: -7.0,
            throttle: 0.0,
        });
        assert_eq!(p.roll, 1500);
        assert_eq!(p.pitch, 1500); // non-finite counts as centred
        assert_eq!(p.yaw, 1100);
    }

    proptest! {
        #[test]
        fn pulses_stay_in_range_and_invert(r in -2f32..2.0, p in -2f32..2.0, y in -2f32..2.0, t in -2f32..2.0) {
            for m in [ChannelMap::ardupilot(), ChannelMap::thesis_naza()] {
                let s = Sticks { roll: r, pitch: p, yaw: y, throttle: t };
                let pulses = m.pulses(&s);
                for a in Axis::ALL {
                    prop_assert!((m.min_us..=m.max_us).contains(&pulses.get(a)));
                }
                let back = m.sticks(&pulses);
                for a in Axis::ALL {
                    prop_assert!((back.get(a) - s.get(a)).abs() <= 1.0 / 350.0);
                }
            }
        }
    }
}
