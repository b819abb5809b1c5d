//! How a report was made: where its inputs came from (stored in the package, or computed) and
//! the wall time of each phase (`motu report --json`'s `sources` and `timings_ms`). Neither is
//! part of what a report says: two reports of the same numbers are equal however they were
//! made (`PartialEq` ignores [`Provenance`]).

use std::time::Instant;

use serde::Serialize;

/// Where each input the package can store came from: `package` (read), `computed` (made
/// here: an older package, another cap, or a table that did not match), `none` (nothing to
/// make: no TLAS over the split cap).
#[derive(Clone, Debug, Default, Serialize)]
pub struct ReportSources {
    /// Per TLAS, the BLASes its instances place (`blas_counts` section).
    pub blas_counts: String,
    /// The stream split (sections 13–17).
    pub stream_split: String,
    /// The streaming floor's proxy clusters (`proxy_clusters` section); `cache` is not used by
    /// the report.
    pub proxy_clusters: String,
}

/// Wall milliseconds per phase, in the order they ran (a JSON object).
#[derive(Clone, Debug, Default)]
pub struct PhaseTimings {
    phases: Vec<(&'static str, f64)>,
}

impl PhaseTimings {
    /// Runs `f`, adding its wall time to phase `name`.
    pub fn time<T>(&mut self, name: &'static str, f: impl FnOnce() -> T) -> T {
        let t = Instant::now();
        let out = f();
        self.add(name, t.elapsed().as_secs_f64() * 1e3);
        out
    }

    /// Adds `ms` to phase `name`.
    pub fn add(&mut self, name: &'static str, ms: f64) {
        match self.phases.iter_mut().find(|(n, _)| *n == name) {
            Some((_, v)) => *v += ms,
            None => self.phases.push((name, ms)),
        }
    }

    /// Phase `name`'s milliseconds.
    pub fn get(&self, name: &str) -> Option<f64> {
        self.phases.iter().find(|(n, _)| *n == name).map(|p| p.1)
    }

    /// Every phase's name.
    pub fn names(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.phases.iter().map(|p| p.0)
    }

    /// The same phases, in the same order, each at 0 ms (tests compare reports byte for byte
    /// but for the times).
    #[cfg(test)]
    pub(crate) fn zeroed(&self) -> PhaseTimings {
        PhaseTimings {
            phases: self.phases.iter().map(|&(n, _)| (n, 0.0)).collect(),
        }
    }
}

impl Serialize for PhaseTimings {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut m = s.serialize_map(Some(self.phases.len()))?;
        for (n, v) in &self.phases {
            // Microsecond resolution is all a wall clock on a loaded machine says.
            m.serialize_entry(n, &((v * 1e3).round() / 1e3))?;
        }
        m.end()
    }
}

/// How a report was made (see the module docs); flattened into the report's JSON.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Provenance {
    pub sources: ReportSources,
    pub timings_ms: PhaseTimings,
}

impl PartialEq for Provenance {
    /// Always equal: how a report was made is not part of what it says.
    fn eq(&self, _: &Self) -> bool {
        true
    }
}
