//! Settings of a registration: [`Config`], its two presets, validation, overrides by name, and
//! [`FIELDS`], the one documented list of fields that the CLI help, `dump-config` and the
//! Python stub are generated from or tested against.

use crate::cloud::Sampling;
use crate::error::{Error, Result};
use crate::search::SearchMethod;

/// The evolutionary algorithm of a run. All share the same task losses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// MTPCR: two populations per edge (original and aiding task) with bi-channel knowledge
    /// sharing (the paper's method).
    Mtpcr,
    /// MFEA (Gupta et al. 2016): one population over all tasks (baseline).
    Mfea,
    /// G-MFEA (Ding et al. 2019): MFEA with decision-variable translation (baseline).
    Gmfea,
}

/// How the clouds given relate to each other.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Order {
    /// Two clouds are one pair; three are the paper's loop; four or more are a set in no known
    /// order (overlapping pairs found, scans joined group by group where loops through them
    /// close).
    Auto,
    /// Three or more clouds given in loop order (cloud k overlaps cloud k + 1, the last
    /// overlaps the first), searched jointly as one loop.
    Given,
}

/// One field of [`Config`]: its name (the same in Rust, Python, CLI flags and config files)
/// and its documentation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Field {
    /// The field's name.
    pub name: &'static str,
    /// Its documentation (the Rust doc comment), lines joined by newlines.
    pub doc: &'static str,
}

impl Field {
    /// The documentation as one line of text (lines joined, whitespace trimmed).
    pub fn text(&self) -> String {
        self.doc
            .lines()
            .map(str::trim)
            .filter(|l| !l.is_empty())
            .collect::<Vec<_>>()
            .join(" ")
    }
}

/// Declares [`Config`] once: every field with its doc comment and its paper value; generates
/// the struct, [`FIELDS`] and [`Config::paper`] from that one list.
macro_rules! settings {
    ($( $(#[doc = $doc:literal])+ $name:ident : $ty:ty = $paper:expr, )+) => {
        /// Every setting of a run. `Config::default()` is the setting recommended for users;
        /// [`Config::paper()`] reproduces the authors' reference implementation step for step.
        /// Each field's doc gives its range and its paper value; the default differs in a few
        /// (see `Config::default`). The field names are the same in Rust, Python keyword
        /// arguments, CLI flags and config files.
        #[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
        #[serde(default, deny_unknown_fields)]
        pub struct Config {
            $( $(#[doc = $doc])+ pub $name: $ty, )+
        }

        /// Every field of [`Config`] in declaration order, with its documentation.
        pub const FIELDS: &[Field] = &[
            $( Field { name: stringify!($name), doc: concat!($($doc, "\n"),+) }, )+
        ];

        impl Config {
            /// The authors' reference setting (the paper's Section IV-C).
            pub fn paper() -> Config {
                Config { $( $name: $paper, )+ }
            }
        }
    };
}

settings! {
    /// The evolutionary algorithm: `mtpcr` (the paper's method), or the baselines `mfea`,
    /// `gmfea`. Paper: mtpcr.
    method: Method = Method::Mtpcr,
    /// How the clouds relate: `auto` (two: a pair; three: the paper's loop; four or more: a
    /// set in no known order, its overlapping pairs found and joined where loops through
    /// them close) or `given` (three or more given in loop order, searched jointly as one
    /// loop). Paper: given.
    order: Order = Order::Given,
    /// Individuals per population (`n`; two populations per edge of the view graph). In
    /// 4..=1000000. Paper: 100.
    population_size: usize = 100,
    /// Generations after the initial one (`G`), at most 1000000; 0: the feature hypotheses,
    /// refined, are the answer (needs `hypotheses` > 0). Paper: 60.
    generations: usize = 60,
    /// Fraction of each cloud's points kept by downsampling, in (0, 1]. Paper: 0.05.
    sample_ratio: f64 = 0.05,
    /// Most points kept per cloud by downsampling (0 = no limit, only `sample_ratio`); with a
    /// limit, dense clouds are thinned evenly before farthest-point sampling, so the cost no
    /// longer grows with the scan's size (beyond the paper). Paper: 0.
    max_sample_points: usize = 0,
    /// Downsampling method: `farthest` (farthest-point sampling) or `random`. Paper: farthest.
    sampling: Sampling = Sampling::Farthest,
    /// Probability per generation and edge of intra-task sharing (aiding <-> original
    /// elites), in [0, 1]. Paper: 0.5.
    p_intra: f64 = 0.5,
    /// Probability per generation and edge of inter-task sharing (the estimate composed from
    /// the rest of the loop), in [0, 1]. Paper: 0.5.
    p_inter: f64 = 0.5,
    /// Fraction of a population kept as elites (and shared per channel), in (0, 1]. Paper: 0.1.
    top_ratio: f64 = 0.1,
    /// Differential-evolution scale factor `F`, in (0, 2]. Paper: 0.5.
    scale_factor: f64 = 0.5,
    /// SBX distribution index at the first generation, in [0, 1000]. Paper: 2.
    sbx_eta_start: f64 = 2.0,
    /// SBX distribution index approached at the last generation, in [0, 1000]. Paper: 10.
    sbx_eta_end: f64 = 10.0,
    /// Weight of the loop-closure term `alpha * tanh(||C - I||_F)` in the original tasks' loss,
    /// finite and >= 0. Paper: 0.05.
    alpha: f64 = 0.05,
    /// The aiding loss caps each point's distance at this fraction of `shift` (the largest
    /// bounding-box side), in (0, 10]. Paper: 0.1.
    aiding_cap_ratio: f64 = 0.1,
    /// Aiding loss in both directions (source -> target and target -> source). Paper: false.
    two_way_aiding: bool = false,
    /// Divide the loop term's translations by `shift` so the term has no unit. Paper: false.
    unit_free_loop_term: bool = false,
    /// Recompute the parents' loop terms each generation from the new bests. Paper: false
    /// (parents keep the loss they were scored with).
    refresh_loop_term: bool = false,
    /// Search structure of the losses: `fast` (occupancy grid and distance field; the same
    /// inlier counts as `exact`) or `exact` (KD-tree; the reference). Paper: fast.
    search: SearchMethod = SearchMethod::Fast,
    /// Independent evolutions (each with its own seed derived from `seed`); the one with the
    /// lowest sum of final original-task costs is kept (beyond the paper). In 1..=1000.
    /// Paper: 1.
    restarts: usize = 1,
    /// Stop the restarts as soon as two of them end on the same transforms (every edge
    /// within 5 degrees; beyond the paper): more restarts would change the cost, not the
    /// answer. Paper: false.
    stop_when_restarts_agree: bool = false,
    /// Iterations of the joint trimmed, residual-weighted point-to-plane ICP of all clouds
    /// after the evolution, which closes the loop exactly (beyond the paper); 0 = off, at most
    /// 10000. Paper: 0.
    refine_iterations: usize = 0,
    /// Pose hypotheses per edge from local features (FPFH keypoints matched both ways,
    /// verified by RANSAC and refined by ICP; beyond the paper), placed in the edge's initial
    /// populations; 0 = off, at most 100. Paper: 0.
    hypotheses: usize = 0,
    /// A pair registered alone whose scans carry viewpoints (scenes) and whose answer the
    /// verdict doubts is registered again from keypoints 0.75 times as far apart, and the
    /// answer the verdict trusts more is kept (beyond the paper): on 300 3DLoMatch pairs 62.7 %
    /// registered instead of 53.0, for a median 0.35 s a pair instead of 0.22 (RESULTS.md).
    /// Loops, sets of scans and scans without viewpoints are not affected. Paper: false.
    second_look: bool = false,
    /// Spacing of the feature keypoints, as a fraction of the clouds' mean principal-axes
    /// box diagonal, in (0, 0.5]. Paper: unused.
    feature_voxel_ratio: f64 = 0.02,
    /// Worker threads for the loss evaluations; 0 = all cores, at most 4096 (more than four
    /// per core are not started). The result does not depend on it.
    num_threads: usize = 0,
    /// Seed of the run; none draws one (reported in the result).
    seed: Option<u64> = None,
}

/// The smallest non-zero `max_sample_points`.
const MIN_SAMPLE_CAP: usize = 100;

impl Default for Config {
    /// The recommended setting: the paper's method with measured changes (RESULTS.md has
    /// the numbers): up to 4 independent evolutions of 8 generations of 30 individuals
    /// per population instead of one of 60 of 100, stopped when two agree; 10 feature
    /// hypotheses per edge in the initial populations (the evolution starts in the right
    /// basins, so a short one suffices); at most 2500 points per sample;
    /// a two-directional aiding loss capped at 0.3 shift instead of 0.1; a final joint ICP
    /// refinement (20 iterations); a second look at a doubted scene pair; scans in no known
    /// order when there are four or more.
    fn default() -> Self {
        Config {
            order: Order::Auto,
            hypotheses: 10,
            max_sample_points: 2500,
            stop_when_restarts_agree: true,
            restarts: 4,
            population_size: 30,
            // The hypotheses, refined, are the answer: 8 generations changed no object result
            // (six problems, turntable48, bunny and N-view suites bit-identical) and added 1
            // registered pair in 300 on each 3DMatch benchmark, for 25 % more time (issue 22).
            generations: 0,
            aiding_cap_ratio: 0.3,
            two_way_aiding: true,
            refine_iterations: 20,
            second_look: true,
            ..Config::paper()
        }
    }
}

impl Config {
    /// Checks every field; the error names the first bad one.
    pub fn validate(&self) -> Result<()> {
        let unit = |v: f64| (0.0..=1.0).contains(&v);
        let n = self.population_size;
        Error::check_setting(
            (4..=1_000_000).contains(&n),
            "population_size",
            "in 4..=1000000",
            n,
        )?;
        Error::check_setting(
            self.generations <= 1_000_000,
            "generations",
            "at most 1000000",
            self.generations,
        )?;
        let r = self.sample_ratio;
        Error::check_setting(r > 0.0 && r <= 1.0, "sample_ratio", "in (0, 1]", r)?;
        let m = self.max_sample_points;
        Error::check_setting(
            m == 0 || m >= MIN_SAMPLE_CAP,
            "max_sample_points",
            "0 or at least 100",
            m,
        )?;
        Error::check_setting(unit(self.p_intra), "p_intra", "in [0, 1]", self.p_intra)?;
        Error::check_setting(unit(self.p_inter), "p_inter", "in [0, 1]", self.p_inter)?;
        let t = self.top_ratio;
        Error::check_setting(t > 0.0 && t <= 1.0, "top_ratio", "in (0, 1]", t)?;
        let f = self.scale_factor;
        Error::check_setting(f > 0.0 && f <= 2.0, "scale_factor", "in (0, 2]", f)?;
        for (field, v) in [
            ("sbx_eta_start", self.sbx_eta_start),
            ("sbx_eta_end", self.sbx_eta_end),
        ] {
            Error::check_setting(
                v.is_finite() && (0.0..=1000.0).contains(&v),
                field,
                "in [0, 1000]",
                v,
            )?;
        }
        let a = self.alpha;
        Error::check_setting(a.is_finite() && a >= 0.0, "alpha", "finite and >= 0", a)?;
        let c = self.aiding_cap_ratio;
        Error::check_setting(c > 0.0 && c <= 10.0, "aiding_cap_ratio", "in (0, 10]", c)?;
        Error::check_setting(
            (1..=1000).contains(&self.restarts),
            "restarts",
            "in 1..=1000",
            self.restarts,
        )?;
        let it = self.refine_iterations;
        Error::check_setting(it <= 10_000, "refine_iterations", "at most 10000", it)?;
        let h = self.hypotheses;
        Error::check_setting(h <= 100, "hypotheses", "at most 100", h)?;
        // Without hypotheses the evolution is the only search: none would be a random pose.
        Error::check_setting(
            h > 0 || self.generations > 0,
            "generations",
            "at least 1 when hypotheses is 0 (without feature hypotheses the evolution is the only search)",
            self.generations,
        )?;
        let v = self.feature_voxel_ratio;
        Error::check_setting(v > 0.0 && v <= 0.5, "feature_voxel_ratio", "in (0, 0.5]", v)?;
        let th = self.num_threads;
        Error::check_setting(
            th <= 4096,
            "num_threads",
            "at most 4096 (0 = all cores)",
            th,
        )?;
        Ok(())
    }

    /// Loss evaluations of a complete run over `tasks` tasks (two per edge: six for the
    /// three-view loop): per restart `tasks n (1 + 2G)` for MTPCR, and `tasks n (tasks + 2G)`
    /// for the baselines (their initial population of `tasks n` is scored on every task).
    pub fn evaluations(&self, tasks: usize) -> usize {
        let (n, g) = (self.population_size, self.generations);
        let per_run = match self.method {
            Method::Mtpcr => tasks * n * (1 + 2 * g),
            Method::Mfea | Method::Gmfea => tasks * n * (tasks + 2 * g),
        };
        self.restarts * per_run
    }

    /// This config with the named fields replaced by `overrides` (field name -> value, as in
    /// a config file or keyword arguments), then validated. An unknown name is
    /// [`Error::UnknownSetting`]; a value of the wrong type or out of range is
    /// [`Error::InvalidConfig`] naming the field. The one place where settings are merged by
    /// name (config files, Python keywords).
    pub fn with_overrides(
        &self,
        overrides: &serde_json::Map<String, serde_json::Value>,
    ) -> Result<Config> {
        let config = self.merged(overrides)?;
        config.validate()?;
        Ok(config)
    }

    /// [`Config::with_overrides`] without the final range check (for layered sources where a
    /// later layer may still fix a value, as CLI flags over a config file).
    pub fn merged(&self, overrides: &serde_json::Map<String, serde_json::Value>) -> Result<Config> {
        let serde_json::Value::Object(base) = serde_json::to_value(self).map_err(|e| {
            Error::InvalidInput(format!("the settings could not be serialised: {e}"))
        })?
        else {
            return Err(Error::InvalidInput("settings are not a map".to_string()));
        };
        let mut merged = base.clone();
        for (key, value) in overrides {
            let Some(field) = FIELDS.iter().find(|f| f.name == key) else {
                return Err(Error::UnknownSetting {
                    name: key.clone(),
                    known: FIELDS.iter().map(|f| f.name).collect::<Vec<_>>().join(", "),
                });
            };
            // serde's message says what is wrong but not where: check each field alone.
            let mut one = base.clone();
            one.insert(key.clone(), value.clone());
            if let Err(e) = serde_json::from_value::<Config>(serde_json::Value::Object(one)) {
                return Err(Error::config(field.name, e.to_string()));
            }
            merged.insert(key.clone(), value.clone());
        }
        serde_json::from_value(serde_json::Value::Object(merged))
            .map_err(|e| Error::InvalidInput(format!("invalid settings: {e}")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_list_every_serialised_field_in_order() {
        let serde_json::Value::Object(map) = serde_json::to_value(Config::default()).unwrap()
        else {
            panic!("a map");
        };
        let names: Vec<&str> = FIELDS.iter().map(|f| f.name).collect();
        let keys: Vec<&str> = map.keys().map(String::as_str).collect();
        let mut sorted = names.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, keys, "serde_json sorts its keys");
        assert_eq!(names[0], "method");
        assert_eq!(*names.last().unwrap(), "seed");
        for f in FIELDS {
            assert!(f.text().len() > 20, "{}: {}", f.name, f.text());
        }
    }

    #[test]
    fn presets_are_valid_and_differ_where_documented() {
        Config::paper().validate().unwrap();
        Config::default().validate().unwrap();
        let (p, d) = (Config::paper(), Config::default());
        assert_eq!((p.restarts, p.generations, p.refine_iterations), (1, 60, 0));
        assert_eq!(
            (
                d.restarts,
                d.population_size,
                d.generations,
                d.refine_iterations
            ),
            (4, 30, 0, 20)
        );
        let e = Config {
            hypotheses: 0,
            ..Config::default()
        }
        .validate()
        .unwrap_err();
        assert!(e.to_string().contains("generations"), "{e}");
        Config {
            hypotheses: 0,
            generations: 1,
            ..Config::default()
        }
        .validate()
        .unwrap();
        assert_eq!(
            (d.order, d.hypotheses, d.max_sample_points),
            (Order::Auto, 10, 2500)
        );
        assert!(d.stop_when_restarts_agree && !p.stop_when_restarts_agree);
        assert_eq!(Config::paper().evaluations(6), 72_600);
    }

    #[test]
    fn overrides_name_the_bad_field() {
        let mut m = serde_json::Map::new();
        m.insert("generations".into(), 7.into());
        assert_eq!(Config::paper().with_overrides(&m).unwrap().generations, 7);
        m.insert("generation".into(), 7.into());
        let e = Config::paper().with_overrides(&m).unwrap_err();
        assert!(matches!(e, Error::UnknownSetting { .. }), "{e}");
        assert!(e.to_string().contains("generation") && e.to_string().contains("alpha"));
        let mut m = serde_json::Map::new();
        m.insert("alpha".into(), "high".into());
        let e = Config::paper().with_overrides(&m).unwrap_err();
        assert!(e.to_string().contains("`alpha`"), "{e}");
        let mut m = serde_json::Map::new();
        m.insert("population_size".into(), 2.into());
        let e = Config::paper().with_overrides(&m).unwrap_err();
        assert!(e.to_string().contains("population_size"), "{e}");
    }
}
