//! What a drone's battery reading says: low (time to fly home), or charged (a swapped pack).
//!
//! A MAVLink autopilot estimates the charge left, in percent; the thesis's shield reports only
//! the pack's voltage. Read by voltage, a LiPo pack is counted in cells from its first reading
//! (a charged cell holds 4.2 V, so `⌈V / 4.25⌉` cells), and judged per cell.

use link::Battery;

/// A reading under this is no pack at all (a vehicle without a voltage sensor), volts.
const NO_PACK_V: f32 = 3.0;

/// When a battery counts as low or as charged.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Low below this charge, percent (vehicles that estimate it).
    pub low_pct: u8,
    /// Low below this voltage per cell (vehicles that report only the voltage), volts …
    pub low_cell_v: f32,
    /// … held this long (a climb sags the voltage for a moment), seconds.
    pub low_for_s: f64,
    /// Charged at this charge or more, percent.
    pub charged_pct: u8,
    /// Charged at this voltage per cell or more, volts.
    pub charged_cell_v: f32,
}

/// One drone's battery as the station follows it.
#[derive(Debug, Clone, Default)]
pub struct Gauge {
    /// Cells of its pack, from the first voltage reading.
    cells: Option<u8>,
    /// Since when the voltage has been low, mission time.
    low_since: Option<f64>,
}

impl Gauge {
    /// The reading (`battery at 24 %`, `battery at 11.1 V`) if the battery at mission time
    /// `now` is low.
    pub fn low(&mut self, now: f64, battery: Option<&Battery>, limits: &Limits) -> Option<String> {
        let battery = battery?;
        if let Some(pct) = battery.remaining_pct {
            return (pct < limits.low_pct).then(|| format!("battery at {pct} %"));
        }
        let v = battery.voltage_v;
        let cells = self.cells(v)?;
        if v >= limits.low_cell_v * f32::from(cells) {
            self.low_since = None;
            return None;
        }
        let since = *self.low_since.get_or_insert(now);
        (now - since >= limits.low_for_s).then(|| format!("battery at {v:.1} V"))
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
        low_pct: 25,
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

    #[test]
    fn a_charge_estimate_is_read_as_it_is() {
        let mut g = Gauge::default();
        let pct = |p| Battery {
            voltage_v: 11.0,
            remaining_pct: Some(p),
        };
        assert_eq!(g.low(0.0, Some(&pct(25)), &LIMITS), None);
        assert_eq!(
            g.low(0.0, Some(&pct(24)), &LIMITS).as_deref(),
            Some("battery at 24 %")
        );
        assert_eq!(g.charged(Some(&pct(89)), &LIMITS), None);
        assert_eq!(g.charged(Some(&pct(90)), &LIMITS).as_deref(), Some("90 %"));
        assert_eq!(g.low(0.0, None, &LIMITS), None);
    }

    #[test]
    fn a_voltage_alone_is_read_per_cell_and_low_only_once_it_stays_low() {
        // A 3S pack, full at first: 11.25 V is its low mark.
        let mut g = Gauge::default();
        assert_eq!(g.low(0.0, Some(&volts(12.5)), &LIMITS), None);
        // A sag in a climb, then back up: not low.
        assert_eq!(g.low(1.0, Some(&volts(11.1)), &LIMITS), None);
        assert_eq!(g.low(3.0, Some(&volts(11.4)), &LIMITS), None);
        assert_eq!(g.low(4.5, Some(&volts(11.1)), &LIMITS), None);
        // Low for 3 s: low.
        assert_eq!(g.low(6.0, Some(&volts(11.2)), &LIMITS), None);
        assert_eq!(
            g.low(7.5, Some(&volts(11.2)), &LIMITS).as_deref(),
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
        assert_eq!(g.low(0.0, Some(&volts(15.2)), &LIMITS), None);
        assert_eq!(g.low(10.0, Some(&volts(15.2)), &LIMITS), None);
        assert!(g.low(20.0, Some(&volts(14.8)), &LIMITS).is_none());
        assert!(g.low(23.5, Some(&volts(14.8)), &LIMITS).is_some());
    }

    #[test]
    fn no_pack_or_a_reading_that_cannot_be_is_neither_low_nor_charged() {
        let mut g = Gauge::default();
        for v in [0.0, 1.2, f32::NAN, f32::INFINITY, -12.0] {
            assert_eq!(g.low(0.0, Some(&volts(v)), &LIMITS), None, "{v}");
            assert_eq!(g.low(10.0, Some(&volts(v)), &LIMITS), None, "{v}");
            assert_eq!(g.charged(Some(&volts(v)), &LIMITS), None, "{v}");
        }
        // The first real reading counts the cells.
        assert_eq!(g.low(0.0, Some(&volts(12.6)), &LIMITS), None);
        assert!(g.charged(Some(&volts(12.6)), &LIMITS).is_some());
    }
}
