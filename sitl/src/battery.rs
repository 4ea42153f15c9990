//! The simulated LiPo pack: its terminal voltage at a charge and a load.
//!
//! A cell's open-circuit voltage follows Tremblay's model (the one behind Simulink's battery
//! block): `E0 − K / s + A·exp(−B·(1 − s))` at charge `s` (0–1) — the exponential zone just off
//! full, the long plateau, the knee near empty. Its constants are fitted to the LiPo chart hobby
//! chargers print (4.20 V full, 3.84 V at half, 3.69 V at 10 %), which it follows within 0.02 V
//! from 5 % to full: a pack like the ones the thesis flew, not the chart itself. Under load the
//! terminal voltage sags by the current times the pack's internal resistance: flying, by
//! [`Pack::sag_v`]; armed on the floor, by a tenth of it (the motors idle); disarmed, not at all.

/// One pack's electrical constants.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pack {
    /// Cells in series.
    pub cells: u8,
    /// Voltage lost to the internal resistance at hover current, for the whole pack, V.
    pub sag_v: f64,
}

impl Default for Pack {
    /// A 3S pack (12.6 V full) sagging 0.24 V at hover: 0.08 V a cell, 20 mΩ at 4 A.
    fn default() -> Self {
        Self {
            cells: 3,
            sag_v: 0.24,
        }
    }
}

/// Tremblay's constants for one cell: `E0`, `K`, `A`, `B`.
const E0: f64 = 3.66;
const K: f64 = 0.0059;
const A: f64 = 0.5459;
const B: f64 = 2.14;

/// The charge below which the model's `1 / s` term is held (a cell at 1 % reads 3.1 V).
const FLOOR: f64 = 0.01;

/// The load on a pack.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Load {
    /// Disarmed: no current.
    None,
    /// Armed on the floor, motors idling.
    Idle,
    /// In the air.
    Flying,
}

impl Pack {
    /// One cell's open-circuit voltage at charge `left` (0–1), V.
    pub fn cell_ocv(left: f64) -> f64 {
        let s = left.clamp(FLOOR, 1.0);
        E0 - K / s + A * (-B * (1.0 - s)).exp()
    }

    /// The pack's terminal voltage at charge `left` (0–1) under `load`, V.
    pub fn voltage(&self, left: f64, load: Load) -> f64 {
        let sag = match load {
            Load::None => 0.0,
            Load::Idle => 0.1 * self.sag_v,
            Load::Flying => self.sag_v,
        };
        f64::from(self.cells) * Self::cell_ocv(left) - sag
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cell_reads_as_a_lipo_from_full_to_empty_and_never_rises_as_it_drains() {
        assert!((Pack::cell_ocv(1.0) - 4.2).abs() < 1e-3);
        // The chart: 3.84 V at half, 3.73 V at 20 %, 3.69 V at 10 %, within 0.02 V.
        for (left, chart) in [(0.5, 3.84), (0.2, 3.73), (0.1, 3.69), (0.8, 4.02)] {
            let v = Pack::cell_ocv(left);
            assert!((v - chart).abs() < 0.02, "{left}: {v}");
        }
        let mut last = f64::INFINITY;
        for i in (0..=100).rev() {
            let v = Pack::cell_ocv(f64::from(i) / 100.0);
            assert!(v <= last && v > 3.0, "{i} %: {v}");
            last = v;
        }
        // Out of range is held at the ends.
        assert_eq!(Pack::cell_ocv(1.5), Pack::cell_ocv(1.0));
        assert_eq!(Pack::cell_ocv(-1.0), Pack::cell_ocv(0.0));
    }

    #[test]
    fn a_pack_sags_under_load_by_its_current() {
        let pack = Pack::default();
        let rest = pack.voltage(0.6, Load::None);
        assert!((rest - 3.0 * Pack::cell_ocv(0.6)).abs() < 1e-12);
        assert!((rest - pack.voltage(0.6, Load::Flying) - 0.24).abs() < 1e-12);
        assert!((rest - pack.voltage(0.6, Load::Idle) - 0.024).abs() < 1e-12);
        assert!((Pack::default().voltage(1.0, Load::None) - 12.6).abs() < 1e-2);
    }
}
