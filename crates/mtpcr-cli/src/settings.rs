//! Settings: flags named like the [`Config`] fields, an optional TOML config file, and the
//! rule that joins them: `Config::default()` (or `Config::paper()` with `--paper`), then the
//! file's keys, then the flags.

use crate::error::{CliResult, Failure};
use clap::Args;
use mtpcr_core::config::FIELDS;
use mtpcr_core::{Config, Method, Order, Sampling, SearchMethod};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Options shared by `register`, `demo` and `eval`: where settings come from, and the
/// progress display.
#[derive(Args, Clone, Debug, Default)]
pub struct RunArgs {
    /// TOML file of settings, with the keys printed by `mtpcr dump-config`; flags override it.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Start from Config::paper() (the authors' reference) instead of Config::default().
    #[arg(long)]
    pub paper: bool,
    /// No progress display on stderr.
    #[arg(long, short)]
    pub quiet: bool,
    #[command(flatten)]
    pub settings: SettingsArgs,
}

/// One flag per [`Config`] field (the flag is the field name with `-` for `_`; `num_threads`
/// is `--threads`). Unset flags keep the config file's or the default value. The help of
/// each flag is the field's documentation in `mtpcr_core::config::FIELDS`, set by
/// [`document`] with its default and paper values.
#[derive(Args, Clone, Debug, Default)]
#[command(next_help_heading = "Settings (config-file keys are the flag names with _ for -)")]
pub struct SettingsArgs {
    #[arg(long, value_name = "ORDER", value_parser = parse_name::<Order>)]
    pub order: Option<Order>,
    #[arg(long, value_name = "METHOD", value_parser = parse_name::<Method>)]
    pub method: Option<Method>,
    #[arg(long, value_name = "N")]
    pub population_size: Option<usize>,
    #[arg(long, value_name = "N")]
    pub generations: Option<usize>,
    #[arg(long, value_name = "RATIO")]
    pub sample_ratio: Option<f64>,
    #[arg(long, value_name = "N")]
    pub max_sample_points: Option<usize>,
    #[arg(long, value_name = "METHOD", value_parser = parse_name::<Sampling>)]
    pub sampling: Option<Sampling>,
    #[arg(long, value_name = "P")]
    pub p_intra: Option<f64>,
    #[arg(long, value_name = "P")]
    pub p_inter: Option<f64>,
    #[arg(long, value_name = "RATIO")]
    pub top_ratio: Option<f64>,
    #[arg(long, value_name = "F")]
    pub scale_factor: Option<f64>,
    #[arg(long, value_name = "ETA")]
    pub sbx_eta_start: Option<f64>,
    #[arg(long, value_name = "ETA")]
    pub sbx_eta_end: Option<f64>,
    #[arg(long, value_name = "WEIGHT")]
    pub alpha: Option<f64>,
    #[arg(long, value_name = "RATIO")]
    pub aiding_cap_ratio: Option<f64>,
    #[arg(long, value_name = "BOOL")]
    pub two_way_aiding: Option<bool>,
    #[arg(long, value_name = "BOOL")]
    pub unit_free_loop_term: Option<bool>,
    #[arg(long, value_name = "BOOL")]
    pub refresh_loop_term: Option<bool>,
    #[arg(long, value_name = "METHOD", value_parser = parse_name::<SearchMethod>)]
    pub search: Option<SearchMethod>,
    #[arg(long, value_name = "N")]
    pub restarts: Option<usize>,
    #[arg(long, value_name = "N")]
    pub refine_iterations: Option<usize>,
    #[arg(long, value_name = "N")]
    pub hypotheses: Option<usize>,
    #[arg(long, value_name = "BOOL")]
    pub second_look: Option<bool>,
    #[arg(long, value_name = "BOOL")]
    pub stop_when_restarts_agree: Option<bool>,
    #[arg(long, value_name = "RATIO")]
    pub feature_voxel_ratio: Option<f64>,
    #[arg(long = "threads", visible_alias = "num-threads", value_name = "N")]
    pub num_threads: Option<usize>,
}

/// Parses a setting given by name (`farthest`, `fast`, `mtpcr`, ...) the way the config file
/// does, so flags and files accept the same names.
fn parse_name<T: serde::de::DeserializeOwned>(s: &str) -> Result<T, String> {
    serde_json::from_value(serde_json::Value::String(s.to_string())).map_err(|e| e.to_string())
}

impl SettingsArgs {
    /// Sets the given flags on `config`; returns the names of the fields they set.
    fn apply(&self, config: &mut Config) -> Vec<&'static str> {
        let mut set = Vec::new();
        macro_rules! apply {
            ($($field:ident),* $(,)?) => {
                $(
                    if let Some(v) = self.$field {
                        config.$field = v;
                        set.push(stringify!($field));
                    }
                )*
            };
        }
        apply!(
            order,
            method,
            population_size,
            generations,
            sample_ratio,
            max_sample_points,
            sampling,
            p_intra,
            p_inter,
            top_ratio,
            scale_factor,
            sbx_eta_start,
            sbx_eta_end,
            alpha,
            aiding_cap_ratio,
            two_way_aiding,
            unit_free_loop_term,
            refresh_loop_term,
            search,
            restarts,
            refine_iterations,
            hypotheses,
            second_look,
            stop_when_restarts_agree,
            feature_voxel_ratio,
            num_threads,
        );
        set
    }
}

/// The flag that sets a config field.
pub fn flag_of(field: &str) -> String {
    match field {
        "num_threads" => "--threads".to_string(),
        _ => format!("--{}", field.replace('_', "-")),
    }
}

/// Joins defaults, the config file and the flags (`seed` is the subcommand's `--seed`), and
/// validates the result (its seed is the flag's, else the file's, else `None`). An error names the file or the field at fault, and where the bad
/// value came from.
pub fn resolve(run: &RunArgs, seed: Option<u64>) -> CliResult<Config> {
    let mut config = if run.paper {
        Config::paper()
    } else {
        Config::default()
    };
    let mut file_keys = Vec::new();
    if let Some(path) = &run.config {
        let (file_config, keys) = read_config_file(path, &config)?;
        config = file_config;
        file_keys = keys;
    }
    let mut from_flags = run.settings.apply(&mut config);
    if let Some(s) = seed {
        config.seed = Some(s);
        from_flags.push("seed");
    }
    if let Err(e) = config.validate() {
        let mut msg = e.to_string();
        if let mtpcr_core::Error::InvalidConfig { field, .. } = &e {
            if from_flags.contains(field) {
                msg.push_str(&format!(" (from {})", flag_of(field)));
            } else if let (Some(path), true) = (&run.config, file_keys.iter().any(|k| k == field)) {
                msg.push_str(&format!(" (in {})", path.display()));
            }
        }
        return Err(Failure(msg));
    }
    Ok(config)
}

/// Reads a TOML config file over `base`: keys in the file replace `base`'s values, the others
/// stay (merged by `Config::merged`; the result is validated after the flags). Returns the config and the keys the file set.
pub fn read_config_file(path: &Path, base: &Config) -> CliResult<(Config, Vec<String>)> {
    let text = std::fs::read_to_string(path).map_err(|e| {
        Failure(format!(
            "{}: cannot read the config file: {e}",
            path.display()
        ))
    })?;
    let bad = |e: &dyn std::fmt::Display| {
        Failure(format!(
            "{}: not a valid mtpcr config file (see `mtpcr dump-config`): {}",
            path.display(),
            e.to_string().trim_end()
        ))
    };
    let file: toml::Table = toml::from_str(&text).map_err(|e| bad(&e))?;
    let keys: Vec<String> = file.keys().cloned().collect();
    let serde_json::Value::Object(overrides) = serde_json::to_value(&file).map_err(|e| bad(&e))?
    else {
        return Err(bad(&"not a table of settings"));
    };
    let config = base.merged(&overrides).map_err(|e| bad(&e))?;
    Ok((config, keys))
}

/// `config` as a TOML document, one key per line with the help text of its flag as a
/// comment above it. `help` maps field names to that text.
pub fn config_toml(
    config: &Config,
    help: &BTreeMap<String, String>,
    title: &str,
) -> CliResult<String> {
    let mut plain = config.clone();
    // TOML integers are i64: a larger seed is written as a comment only.
    let big_seed = config.seed.filter(|&s| i64::try_from(s).is_err());
    if big_seed.is_some() {
        plain.seed = None;
    }
    let body = toml::to_string(&plain)
        .map_err(|e| Failure(format!("cannot write the settings as TOML: {e}")))?;
    let mut out = String::new();
    out.push_str(&format!("# {title}\n"));
    out.push_str("# Use it with `mtpcr register|demo|eval ... --config FILE`; flags override these values,\n");
    out.push_str("# a key left out keeps its default, an unknown key is an error.\n");
    for line in body.lines() {
        let key = line.split('=').next().unwrap_or("").trim();
        if let Some(h) = help.get(key) {
            out.push_str(&format!("\n# {h}\n"));
        }
        out.push_str(line);
        out.push('\n');
    }
    match (config.seed, big_seed) {
        (None, _) => out.push_str(
            "\n# Seed of the run; left out, each run draws one and reports it.\n# seed = 1\n",
        ),
        (Some(s), Some(_)) => out.push_str(&format!(
            "\n# seed = {s} is beyond a TOML integer: pass it as `--seed {s}`.\n"
        )),
        _ => {}
    }
    Ok(out)
}

/// The documentation of each config field (from `mtpcr_core::config::FIELDS`), one line each.
pub fn field_help() -> BTreeMap<String, String> {
    FIELDS
        .iter()
        .map(|f| (f.name.to_string(), f.text()))
        .collect()
}

/// A setting's value as the CLI and config files write it (`fast`, `0.05`, `true`, `none`).
fn shown(value: &serde_json::Value) -> String {
    match value {
        serde_json::Value::String(s) => s.clone(),
        serde_json::Value::Null => "none".to_string(),
        v => v.to_string(),
    }
}

/// `cmd` with the help of every settings flag of its subcommands taken from the core's field
/// documentation, followed by the default and paper values.
pub fn document(mut cmd: clap::Command) -> clap::Command {
    let values = |c: Config| match serde_json::to_value(c) {
        Ok(serde_json::Value::Object(m)) => m,
        _ => serde_json::Map::new(),
    };
    let (default, paper) = (values(Config::default()), values(Config::paper()));
    let subcommands: Vec<String> = cmd
        .get_subcommands()
        .map(|s| s.get_name().to_string())
        .collect();
    for sub in subcommands {
        cmd = cmd.mut_subcommand(sub, |mut sc| {
            for field in FIELDS {
                if field.name == "seed" || sc.get_arguments().all(|a| a.get_id() != field.name) {
                    continue;
                }
                let text = field.text();
                let values = match (default.get(field.name), paper.get(field.name)) {
                    (Some(d), Some(p)) => format!(" [default: {}; paper: {}]", shown(d), shown(p)),
                    _ => String::new(),
                };
                let short = text
                    .split(". ")
                    .next()
                    .unwrap_or(&text)
                    .trim_end_matches('.')
                    .to_string();
                sc = sc.mut_arg(field.name, |a| {
                    a.help(format!("{short}{values}"))
                        .long_help(format!("{text}{values}"))
                });
            }
            sc
        });
    }
    cmd
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    /// Every config field (including ones added to `Config` later) must have a flag on every
    /// subcommand that runs a registration.
    #[test]
    fn every_config_field_has_a_flag() {
        let cli = crate::Cli::command();
        let serde_json::Value::Object(fields) = serde_json::to_value(Config::default()).unwrap()
        else {
            panic!("Config serialises to a map");
        };
        assert!(fields.len() >= 20, "{fields:?}");
        for sub in ["register", "demo", "eval"] {
            let cmd = cli.find_subcommand(sub).unwrap();
            let mut longs: Vec<String> = Vec::new();
            for a in cmd.get_arguments() {
                longs.extend(a.get_long().map(str::to_string));
                longs.extend(
                    a.get_all_aliases()
                        .unwrap_or_default()
                        .into_iter()
                        .map(str::to_string),
                );
            }
            for field in fields.keys() {
                let dashed = field.replace('_', "-");
                assert!(
                    longs.contains(&dashed),
                    "config field `{field}` has no flag `--{dashed}` on `mtpcr {sub}`"
                );
            }
        }
    }

    #[test]
    fn flag_help_is_the_core_field_doc_with_its_defaults() {
        let cli = document(crate::Cli::command());
        let register = cli.find_subcommand("register").unwrap();
        let help = |id: &str| {
            let arg = register.get_arguments().find(|a| a.get_id() == id).unwrap();
            (
                arg.get_help().unwrap().to_string(),
                arg.get_long_help().unwrap().to_string(),
            )
        };
        let (short, long) = help("alpha");
        assert!(
            short.starts_with("Weight of the loop-closure term"),
            "{short}"
        );
        assert!(short.ends_with("[default: 0.05; paper: 0.05]"), "{short}");
        let doc = FIELDS.iter().find(|f| f.name == "alpha").unwrap().text();
        assert!(long.starts_with(&doc), "{long}");
        let (short, _) = help("restarts");
        assert!(short.contains("[default: 4; paper: 1]"), "{short}");
        let (short, _) = help("search");
        assert!(short.contains("[default: fast; paper: fast]"), "{short}");
    }

    #[test]
    fn flags_set_their_fields() {
        let s = SettingsArgs {
            generations: Some(7),
            num_threads: Some(2),
            sampling: Some(Sampling::Random),
            ..SettingsArgs::default()
        };
        let mut c = Config::default();
        let set = s.apply(&mut c);
        assert_eq!(
            (c.generations, c.num_threads, c.sampling),
            (7, 2, Sampling::Random)
        );
        assert_eq!(set, ["generations", "sampling", "num_threads"]);
    }

    #[test]
    fn dumped_defaults_parse_back_and_carry_help() {
        let help = field_help();
        assert!(help.contains_key("population_size") && help.contains_key("num_threads"));
        for base in [Config::default(), Config::paper()] {
            let text = config_toml(&base, &help, "test").unwrap();
            assert!(text.contains("# Individuals per population"), "{text}");
            let back: Config = toml::from_str(&text).unwrap();
            assert_eq!(back, base);
        }
        let seeded = Config {
            seed: Some(u64::MAX),
            ..Config::default()
        };
        let back: Config = toml::from_str(&config_toml(&seeded, &help, "t").unwrap()).unwrap();
        assert_eq!(back.seed, None);
        let seeded = Config {
            seed: Some(42),
            ..Config::default()
        };
        let back: Config = toml::from_str(&config_toml(&seeded, &help, "t").unwrap()).unwrap();
        assert_eq!(back, seeded);
    }

    #[test]
    fn file_keys_override_the_base_and_flags_override_the_file() {
        let dir = std::env::temp_dir().join(format!("mtpcr-cli-settings-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("c.toml");
        std::fs::write(&path, "generations = 9\nalpha = 0.2\nseed = 5\n").unwrap();
        let run = RunArgs {
            config: Some(path.clone()),
            settings: SettingsArgs {
                alpha: Some(0.3),
                ..SettingsArgs::default()
            },
            ..RunArgs::default()
        };
        let c = resolve(&run, None).unwrap();
        assert_eq!((c.generations, c.alpha, c.seed), (9, 0.3, Some(5)));
        assert_eq!(c.population_size, Config::default().population_size);
        assert_eq!(resolve(&run, Some(8)).unwrap().seed, Some(8));

        std::fs::write(&path, "generation = 9\n").unwrap();
        let e = resolve(&run, None).unwrap_err().0;
        assert!(e.contains("c.toml") && e.contains("generation"), "{e}");
        std::fs::write(&path, "population_size = 2\n").unwrap();
        let e = resolve(&run, None).unwrap_err().0;
        assert!(e.contains("population_size") && e.contains("c.toml"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
