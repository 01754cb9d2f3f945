//! How a followed identification holds the MIT-UKF's entries (see
//! [`VehicleFilters::hold_class`]).

use super::*;

/// A fit's gamma and delta of actuator `j` (of `l`) as `reseat_entries` takes them.
pub(super) fn fit_entries(j: usize, l: usize, c: &Identified) -> [(usize, f64, f64); 2] {
    [
        (3 + j, c.gamma, c.gamma_std * c.gamma_std),
        (3 + l + j, c.delta, c.delta_std * c.delta_std),
    ]
}

impl<const N: usize, const M: usize, const S: usize> FilterPair<N, M, S> {
    /// The MIT-UKF's next update leaves the entries actuator `k`'s last fit reseats (those
    /// `reseat_entries` takes) as they are.
    pub(super) fn consider_last_fit(&mut self, k: usize) {
        let l = (N - 3) / 2;
        let Some(c) = self.last_fit[k] else { return };
        for e in fit_entries(k, l, &c)
            .iter()
            .filter(|e| crate::estimate::ukf::reseatable::<N>(e))
        {
            self.ukf.ukf.consider[e.0] = true;
        }
    }

    /// After a release, while the class stands, the coefficient it leaves unchanged (an
    /// offset's gain, a loss's bias) is reseated at the last fit, value and spread, and the
    /// MIT-UKF's updates leave it there (a consider state, as while the fit is followed): the
    /// class says where it is, and the release only says that the innovations moved (the
    /// fault's changed coefficient grew or went back, or a strong gust). Left to the updates,
    /// which take the gusts for white noise, a gust's release can move an offset's unchanged
    /// gain far from 1 within a second, its bounds excluding 1, while the class says bias
    /// (measured on the plane's aileron offset). Reseated on every step, not only
    /// held: a class that changes and comes back finds it at the fit, not where the updates
    /// had taken it meanwhile, and a consider state's variance, which no update reduces,
    /// does not grow with the process noise.
    pub(super) fn hold_unchanged(&mut self, k: usize, kind: IdentifiedKind) {
        let l = (N - 3) / 2;
        let Some(c) = self.last_fit[k] else { return };
        let [gain, bias] = fit_entries(k, l, &c);
        let entry = match kind {
            IdentifiedKind::Offset => gain,
            IdentifiedKind::Gain => bias,
            IdentifiedKind::Stuck => return,
        };
        if crate::estimate::ukf::reseatable::<N>(&entry) {
            self.ukf.reseat_entries(&[entry]);
            self.ukf.ukf.consider[entry.0] = true;
        }
    }
}
