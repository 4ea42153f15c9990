//! What a drone's battery reading says: low (time to fly home), or charged (a swapped pack).
//!
//! A MAVLink autopilot estimates the charge left, in percent. Then "low" is sized to the way
//! home, as DJI's smart return-to-home and PX4's RTL time estimate (a factor times the time
//! home, plus a margin) size it: the pack's drain is measured in the air, and a drone turns home
//! once what is left, less a reserve, would only just bring it back from where it is (with a
//! margin). A drone near its start flies on down to the reserve; one far away turns early. On a
//! fixed 25 % a drone far out in building 31 did not get home (its vehicle's failsafe landed it
//! at 10 % on the way), while drones near home turned early.
//!
//! The thesis's shield reports only the pack's voltage, which sags under load and says little
//! about the charge until late: read by voltage, a LiPo pack is counted in cells from its first
//! reading (a charged cell holds 4.2 V, so `⌈V / 4.25⌉` cells), and judged per cell.

use link::Battery;

/// A reading under this is no pack at all (a vehicle without a voltage sensor), volts.
const NO_PACK_V: f32 = 3.0;

/// A charge this much above the last one read is another pack (swapped), percent.
const NEW_PACK_PCT: u8 = 5;

/// Time between two readings counted as flown at most (a longer gap: on the ground, or the link
/// silent), seconds.
const MAX_GAP_S: f64 = 1.0;

/// When a battery counts as low or as charged.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Low below this charge wherever the drone is, percent (vehicles that estimate it): what
    /// must be left on landing.
    pub reserve_pct: u8,
    /// The way home is taken to be flown at this pace, m/s …
    pub home_pace_mps: f64,
    /// … plus this long to turn onto it and land, seconds …
    pub turn_and_land_s: f64,
    /// … and the charge that needs, at the drain measured so far, times this.
    pub home_margin: f64,
    /// The drain is measured once this much of a pack is used in the air, percent (the charge
    /// is read in whole percent).
    pub drain_after_pct: u8,
    /// Low below this voltage per cell (vehicles that report only the voltage), volts …
    pub low_cell_v: f32,
    /// … held this long (a climb sags the voltage for a moment), seconds.
    pub low_for_s: f64,
    /// Charged at this charge or more, percent.
    pub charged_pct: u8,
    /// Charged at this voltage per cell or more, volts.
    pub charged_cell_v: f32,
}

/// A low battery: why the drone goes home.
#[derive(Debug, Clone, PartialEq)]
pub struct Low {
    /// The reading (`battery at 24 %`, `battery at 11.1 V`).
    pub reading: String,
    /// What the way home needs when that, not the reserve, made it low (`41 m from its start:
    /// about 17 % to get there and land`).
    pub way_home: Option<String>,
}

/// One drone's battery as the station follows it.
#[derive(Debug, Clone, Default)]
pub struct Gauge {
    /// Cells of its pack, from the first voltage reading.
    cells: Option<u8>,
    /// Since when the voltage has been low, mission time.
    low_since: Option<f64>,
    /// This pack's use in the air.
    drain: Option<Drain>,
    /// The charge it turns home at from where it was at the last reading, percent.
    home_at: Option<f64>,
}

/// A pack's charge used over the time flown on it.
#[derive(Debug, Clone, Copy)]
struct Drain {
    first_pct: u8,
    last_pct: u8,
    last_t: f64,
    flown_s: f64,
}

impl Drain {
    /// Percent a second, once enough of the pack is used to tell.
    fn rate(&self, limits: &Limits) -> Option<f64> {
        let used = self.first_pct.saturating_sub(self.last_pct);
        (used >= limits.drain_after_pct.max(1) && self.flown_s > 0.0)
            .then(|| f64::from(used) / self.flown_s)
    }
}

impl Gauge {
    /// Whether the battery of a flying drone at mission time `now` is low, with `home_m` the
    /// length of its way home (metres, `None`: unknown). Called at every control step in the
    /// air: the pack's drain is measured from these readings.
    pub fn low(
        &mut self,
        now: f64,
        battery: Option<&Battery>,
        home_m: Option<f64>,
        limits: &Limits,
    ) -> Option<Low> {
        let battery = battery?;
        if let Some(pct) = battery.remaining_pct {
            return self.low_charge(now, pct, home_m, limits);
        }
        let v = battery.voltage_v;
        let cells = self.cells(v)?;
        if v >= limits.low_cell_v * f32::from(cells) {
            self.low_since = None;
            return None;
        }
        let since = *self.low_since.get_or_insert(now);
        (now - since >= limits.low_for_s).then(|| Low {
            reading: format!("battery at {v:.1} V"),
            way_home: None,
        })
    }

    fn low_charge(
        &mut self,
        now: f64,
        pct: u8,
        home_m: Option<f64>,
        limits: &Limits,
    ) -> Option<Low> {
        let drain = match self.drain {
            Some(mut d) if pct <= d.last_pct.saturating_add(NEW_PACK_PCT) => {
                d.flown_s += (now - d.last_t).clamp(0.0, MAX_GAP_S);
                d.last_t = now;
                d.last_pct = d.last_pct.min(pct);
                d
            }
            _ => Drain {
                first_pct: pct,
                last_pct: pct,
                last_t: now,
                flown_s: 0.0,
            },
        };
        self.drain = Some(drain);
        self.home_at = None;
        let reading = format!("battery at {pct} %");
        if pct < limits.reserve_pct {
            return Some(Low {
                reading,
                way_home: None,
            });
        }
        let (rate, home_m) = (drain.rate(limits)?, home_m?);
        let home_s = home_m.max(0.0) / limits.home_pace_mps.max(0.01) + limits.turn_and_land_s;
        let need = rate * home_s * limits.home_margin;
        self.home_at = Some(f64::from(limits.reserve_pct) + need);
        (f64::from(pct) < f64::from(limits.reserve_pct) + need).then(|| Low {
            reading,
            way_home: Some(format!(
                "{home_m:.0} m from its start: about {need:.0} % to get there and land, {} % to spare",
                limits.reserve_pct
            )),
        })
    }

    /// The charge at which the drone turns home from where it was at the last reading (the
    /// reserve and what its way home needs), percent; `None` until the pack's drain and the way
    /// home are known, and for a voltage alone. What the operator watches beside the charge.
    pub fn home_at_pct(&self) -> Option<f64> {
        self.home_at
    }

    /// The reading (`100 %`, `12.6 V`) if the battery is a charged one.
    pub fn charged(&mut self, battery: Option<&Battery>, limits: &Limits) -> Option<String> {
        let battery = battery?;
        if let Some(pct) = battery.remaining_pct {
            return (pct >= limits.charged_pct).then(|| format!("{pct} %"));
        }
        let v = battery.voltage_v;
        let cells = self.cells(v)?;
        (v >= limits.charged_cell_v * f32::from(cells)).then(|| format!("{v:.1} V"))
    }

    /// The pack's cells, counted at the first reading of a pack.
    fn cells(&mut self, voltage_v: f32) -> Option<u8> {
        if !(voltage_v.is_finite() && voltage_v >= NO_PACK_V) {
            return None;
        }
        Some(
            *self
                .cells
                .get_or_insert(((voltage_v / 4.25).ceil() as u8).max(1)),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMITS: Limits = Limits {
        reserve_pct: 15,
        home_pace_mps: 0.4,
        turn_and_land_s: 15.0,
        home_margin: 1.5,
        drain_after_pct: 5,
        low_cell_v: 3.75,
        low_for_s: 3.0,
        charged_pct: 90,
        charged_cell_v: 4.1,
    };

    fn volts(v: f32) -> Battery {
        Battery {
            voltage_v: v,
            remaining_pct: None,
        }
    }

    fn pct(p: u8) -> Battery {
        Battery {
            voltage_v: 11.0,
            remaining_pct: Some(p),
        }
    }

    /// The reading if low.
    fn low(g: &mut Gauge, t: f64, b: Option<&Battery>, home_m: Option<f64>) -> Option<String> {
        g.low(t, b, home_m, &LIMITS).map(|l| l.reading)
    }

    #[test]
    fn a_charge_estimate_is_low_under_the_reserve_wherever_the_drone_is() {
        let mut g = Gauge::default();
        assert_eq!(low(&mut g, 0.0, Some(&pct(15)), Some(0.0)), None);
        assert_eq!(
            low(&mut g, 0.1, Some(&pct(14)), None).as_deref(),
            Some("battery at 14 %")
        );
        assert_eq!(g.charged(Some(&pct(89)), &LIMITS), None);
        assert_eq!(g.charged(Some(&pct(90)), &LIMITS).as_deref(), Some("90 %"));
        assert_eq!(low(&mut g, 0.2, None, Some(0.0)), None);
    }

    /// A pack drained as the simulator's is in the air (12 minutes from full to empty), read
    /// every 0.1 s from mission time `from` for `seconds`; the first reading at which it was low.
    fn fly(g: &mut Gauge, from: f64, seconds: f64, full: f64, home_m: f64) -> Option<(f64, Low)> {
        (0..(seconds * 10.0) as usize).find_map(|i| {
            let t = from + i as f64 * 0.1;
            let left = (full - (t - from) / 720.0 * 100.0).max(0.0);
            g.low(t, Some(&pct(left.round() as u8)), Some(home_m), &LIMITS)
                .map(|l| (t, l))
        })
    }

    #[test]
    fn a_drone_turns_home_with_what_its_way_home_needs_from_the_drain_measured_in_the_air() {
        // 30 m out: 75 s at 0.4 m/s and 15 s to turn and land, at 100/720 % a second, times
        // 1.5, is 18.9 %: it turns on reading 33 % (< 15 + 18.9; from 478.8 s).
        let mut g = Gauge::default();
        assert_eq!(g.home_at_pct(), None);
        let (t, why) = fly(&mut g, 0.0, 720.0, 100.0, 30.0).expect("low");
        assert!((478.7..479.0).contains(&t), "{t}");
        assert_eq!(why.reading, "battery at 33 %");
        // What the operator is shown beside the charge: it turns home at 33.9 %.
        let home_at = g.home_at_pct().expect("known");
        assert!((33.8..34.0).contains(&home_at), "{home_at}");
        assert_eq!(
            why.way_home.as_deref(),
            Some("30 m from its start: about 19 % to get there and land, 15 % to spare")
        );
        // A metre from its start it flies on to the reserve and the 3.7 % it needs to land
        // there: it turns on reading 18 % (from 586.8 s).
        let (t, why) = fly(&mut Gauge::default(), 0.0, 720.0, 100.0, 1.0).expect("low");
        assert!((586.7..587.0).contains(&t), "{t}");
        assert_eq!(why.reading, "battery at 18 %");
        // Far away, on a pack half used when first read, the drain is only known once 5 % more
        // is used (reading 45 %, from 132.4 s): the turn comes then, not before and not later.
        let (t, why) = fly(&mut Gauge::default(), 100.0, 720.0, 50.0, 60.0).expect("low");
        assert!((132.0..133.0).contains(&t), "{t}");
        assert_eq!(why.reading, "battery at 45 %");
        assert!(
            why.way_home
                .is_some_and(|w| w.starts_with("60 m from its start"))
        );
    }

    #[test]
    fn the_drain_counts_time_flown_on_this_pack_only() {
        // 300 s in the air on a pack (58 % left), then landed for 10 minutes and up again on the
        // same pack: the time on the ground does not thin the measured drain.
        let mut g = Gauge::default();
        assert!(fly(&mut g, 0.0, 300.0, 100.0, 30.0).is_none());
        let (t, _) = fly(&mut g, 900.0, 600.0, 58.3, 30.0).expect("low");
        assert!((1078.5..1079.0).contains(&t), "{t}");
        // A charged pack put in is a new pack: its drain is measured afresh, so a pack whose
        // drain is not yet known is low only under the reserve.
        let mut g = Gauge::default();
        assert!(fly(&mut g, 0.0, 300.0, 100.0, 30.0).is_none());
        assert!(g.home_at_pct().is_some());
        assert_eq!(low(&mut g, 400.0, Some(&pct(100)), Some(30.0)), None);
        assert_eq!(low(&mut g, 400.1, Some(&pct(97)), Some(500.0)), None);
        assert_eq!(g.home_at_pct(), None, "not known on the new pack yet");
        // Its way home unknown, a drone is low only under the reserve.
        let mut g = Gauge::default();
        assert!(fly(&mut g, 0.0, 600.0, 100.0, 30.0).is_some());
        assert_eq!(low(&mut g, 600.1, Some(&pct(16)), None), None);
        assert_eq!(
            low(&mut g, 600.2, Some(&pct(14)), None).as_deref(),
            Some("battery at 14 %")
        );
    }

    #[test]
    fn a_voltage_alone_is_read_per_cell_and_low_only_once_it_stays_low() {
        // A 3S pack, full at first: 11.25 V is its low mark.
        let mut g = Gauge::default();
        assert_eq!(low(&mut g, 0.0, Some(&volts(12.5)), None), None);
        // A sag in a climb, then back up: not low.
        assert_eq!(low(&mut g, 1.0, Some(&volts(11.1)), None), None);
        assert_eq!(low(&mut g, 3.0, Some(&volts(11.4)), None), None);
        assert_eq!(low(&mut g, 4.5, Some(&volts(11.1)), None), None);
        // Low for 3 s: low.
        assert_eq!(low(&mut g, 6.0, Some(&volts(11.2)), None), None);
        assert_eq!(
            low(&mut g, 7.5, Some(&volts(11.2)), None).as_deref(),
            Some("battery at 11.2 V")
        );
        // The same pack is still 3 cells when low; a charged one reads 4.1 V a cell.
        assert_eq!(g.charged(Some(&volts(12.2)), &LIMITS), None);
        assert_eq!(
            g.charged(Some(&volts(12.6)), &LIMITS).as_deref(),
            Some("12.6 V")
        );
        // A 4S pack first seen half charged is 4 cells: 15.2 V is not low.
        let mut g = Gauge::default();
        assert_eq!(low(&mut g, 0.0, Some(&volts(15.2)), None), None);
        assert_eq!(low(&mut g, 10.0, Some(&volts(15.2)), None), None);
        assert!(low(&mut g, 20.0, Some(&volts(14.8)), None).is_none());
        assert!(low(&mut g, 23.5, Some(&volts(14.8)), None).is_some());
    }

    #[test]
    fn no_pack_or_a_reading_that_cannot_be_is_neither_low_nor_charged() {
        let mut g = Gauge::default();
        for v in [0.0, 1.2, f32::NAN, f32::INFINITY, -12.0] {
            assert_eq!(low(&mut g, 0.0, Some(&volts(v)), None), None, "{v}");
            assert_eq!(low(&mut g, 10.0, Some(&volts(v)), None), None, "{v}");
            assert_eq!(g.charged(Some(&volts(v)), &LIMITS), None, "{v}");
        }
        // The first real reading counts the cells.
        assert_eq!(low(&mut g, 0.0, Some(&volts(12.6)), None), None);
        assert!(g.charged(Some(&volts(12.6)), &LIMITS).is_some());
    }
}
