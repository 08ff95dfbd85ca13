//! A suite's seed axis (`seeds = [1, 2, 3]` or `seeds = "1..=9"`) and the summary of its runs
//! across seeds: per scene and method the relMSE's mean and median, the per-seed ratios to
//! the baseline method and the spread of the image means.

use super::RunResult;
use serde::Deserialize;
use std::fmt::Write as _;

/// The seeds a suite renders each run with, in the order given.
#[derive(Clone, Debug, PartialEq)]
pub struct Seeds(pub Vec<u64>);

impl<'de> Deserialize<'de> for Seeds {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Seeds, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            List(Vec<i64>),
            Range(String),
        }
        let seeds = match Raw::deserialize(d).map_err(|_| {
            serde::de::Error::custom("`seeds` must be a list of seeds ([1, 2, 3]) or a range (\"1..=9\", \"1..10\")")
        })? {
            Raw::List(v) => v
                .into_iter()
                .map(|s| u64::try_from(s).map_err(|_| format!("a seed must not be negative, got {s}")))
                .collect::<Result<Vec<u64>, String>>(),
            Raw::Range(r) => parse_range(&r),
        }
        .map_err(serde::de::Error::custom)?;
        Seeds::new(seeds).map_err(serde::de::Error::custom)
    }
}

impl Seeds {
    /// The seeds `seeds`: at least one, none twice.
    pub fn new(seeds: Vec<u64>) -> Result<Seeds, String> {
        if seeds.is_empty() {
            return Err("`seeds` names no seed".into());
        }
        let mut sorted = seeds.clone();
        sorted.sort_unstable();
        if let Some(w) = sorted.windows(2).find(|w| w[0] == w[1]) {
            return Err(format!("`seeds` names seed {} twice", w[0]));
        }
        Ok(Seeds(seeds))
    }

    /// Seeds written on a command line: a range (`1..=9`, `1..10`) or a list (`1,2,5`).
    pub fn parse(s: &str) -> Result<Seeds, String> {
        let seeds = if s.contains("..") {
            parse_range(s)?
        } else {
            s.split(',')
                .map(|x| {
                    x.trim()
                        .parse::<u64>()
                        .map_err(|_| format!("\"{s}\" is not a list (1,2,5) or range (1..=9) of seeds"))
                })
                .collect::<Result<Vec<u64>, String>>()?
        };
        Seeds::new(seeds)
    }
}

/// `"A..=B"` (B included) or `"A..B"` (B excluded).
fn parse_range(r: &str) -> Result<Vec<u64>, String> {
    let bad = || format!("`seeds = \"{r}\"` is not a range of seeds (\"1..=9\" or \"1..10\")");
    let (a, b, inclusive) = match (r.split_once("..="), r.split_once("..")) {
        (Some((a, b)), _) => (a, b, true),
        (None, Some((a, b))) => (a, b, false),
        (None, None) => return Err(bad()),
    };
    let (a, b): (u64, u64) = (a.trim().parse().map_err(|_| bad())?, b.trim().parse().map_err(|_| bad())?);
    let end = if inclusive { b.checked_add(1).ok_or_else(bad)? } else { b };
    if end <= a {
        return Err(format!("`seeds = \"{r}\"` is empty"));
    }
    Ok((a..end).collect())
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    match s.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => s[n / 2],
        n => 0.5 * (s[n / 2 - 1] + s[n / 2]),
    }
}

/// The summary across seeds (Markdown): for each scene and method, over the seeds that ran
/// it, the relMSE's mean and median, the mean and median of its per-seed ratio to the
/// baseline's relMSE (and on how many seeds it is below it), the inefficiency (relMSE × s)
/// and the image mean's ratio to the reference (median, least and greatest), then the
/// relMSE seed by seed.
pub fn summary(name: &str, runs: &[(u64, Vec<RunResult>)], baseline: &str) -> String {
    let seeds: Vec<u64> = runs.iter().map(|(s, _)| *s).collect();
    let mut pairs: Vec<(String, String)> = Vec::new();
    for (_, results) in runs {
        for r in results {
            let key = (r.scene.clone(), r.method.clone());
            if !pairs.contains(&key) {
                pairs.push(key);
            }
        }
    }
    let find = |results: &[RunResult], scene: &str, method: &str| {
        results.iter().find(|r| r.scene == scene && r.method == method).cloned()
    };
    let mut s = format!(
        "# {name}: summary over {} seeds ({})\n\n| scene | method | seeds | relMSE mean | relMSE median | ratio to {baseline}: mean | median | seeds below | relMSE × s mean | image mean ratio: median | least | greatest |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n",
        seeds.len(),
        seeds.iter().map(u64::to_string).collect::<Vec<_>>().join(", ")
    );
    let mut by_seed = String::new();
    for (scene, method) in &pairs {
        let mine: Vec<(u64, RunResult)> =
            runs.iter().filter_map(|(seed, rs)| find(rs, scene, method).map(|r| (*seed, r))).collect();
        let relmse: Vec<f64> = mine.iter().map(|(_, r)| r.relmse).collect();
        let inefficiency: Vec<f64> = mine.iter().map(|(_, r)| r.relmse * r.seconds).collect();
        let means: Vec<f64> = mine.iter().map(|(_, r)| r.mean_ratio).collect();
        let ratios: Vec<f64> = runs
            .iter()
            .filter_map(|(_, rs)| Some(find(rs, scene, method)?.relmse / find(rs, scene, baseline)?.relmse))
            .collect();
        let below = ratios.iter().filter(|&&x| x < 1.0).count();
        let (least, greatest) = means.iter().fold((f64::MAX, f64::MIN), |(a, b), &m| (a.min(m), b.max(m)));
        let _ = writeln!(
            s,
            "| {scene} | {method} | {} | {:.5} | {:.5} | {} | {} | {} | {:.4} | {:.4} | {:.4} | {:.4} |",
            mine.len(),
            mean(&relmse),
            median(&relmse),
            if ratios.is_empty() { String::new() } else { format!("{:.3}", mean(&ratios)) },
            if ratios.is_empty() { String::new() } else { format!("{:.3}", median(&ratios)) },
            if ratios.is_empty() { String::new() } else { format!("{below} of {}", ratios.len()) },
            mean(&inefficiency),
            median(&means),
            least,
            greatest
        );
        let cells: Vec<String> = seeds
            .iter()
            .map(|seed| mine.iter().find(|(s, _)| s == seed).map_or(String::new(), |(_, r)| format!("{:.5}", r.relmse)))
            .collect();
        let _ = writeln!(by_seed, "| {scene} | {method} | {} |", cells.join(" | "));
    }
    let _ = write!(
        s,
        "\n## relMSE seed by seed\n\n| scene | method | {} |\n|---|---|{}\n{by_seed}",
        seeds.iter().map(|s| format!("seed {s}")).collect::<Vec<_>>().join(" | "),
        "---|".repeat(seeds.len())
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seeds(text: &str) -> Result<Seeds, String> {
        #[derive(Deserialize)]
        struct F {
            seeds: Seeds,
        }
        toml::from_str::<F>(text).map(|f| f.seeds).map_err(|e| e.message().to_string())
    }

    #[test]
    fn seed_lists_and_ranges_parse_and_malformed_ones_are_refused() {
        assert_eq!(seeds("seeds = [3, 1, 2]").unwrap(), Seeds(vec![3, 1, 2]));
        assert_eq!(seeds("seeds = \"1..=4\"").unwrap(), Seeds(vec![1, 2, 3, 4]));
        assert_eq!(seeds("seeds = \"10..12\"").unwrap(), Seeds(vec![10, 11]));
        for (bad, says) in [
            ("seeds = []", "no seed"),
            ("seeds = [1, 2, 1]", "seed 1 twice"),
            ("seeds = [-1]", "negative"),
            ("seeds = \"9..=1\"", "empty"),
            ("seeds = \"1-9\"", "not a range"),
            ("seeds = \"a..=b\"", "not a range"),
            ("seeds = 4", "a list of seeds"),
            ("seeds = [1.5]", "a list of seeds"),
        ] {
            let e = seeds(bad).unwrap_err();
            assert!(e.contains(says), "{bad}: {e}");
        }
    }

    fn run(scene: &str, method: &str, relmse: f64, mean_ratio: f64) -> RunResult {
        RunResult {
            scene: scene.into(),
            method: method.into(),
            seed: 0,
            spp: 1,
            seconds: 2.0,
            samples_per_second: 1.0,
            relmse,
            flip: 0.0,
            mean_ratio,
            curve: Vec::new(),
            phases: None,
        }
    }

    #[test]
    fn summary_gives_means_medians_and_per_seed_ratios() {
        let runs = vec![
            (1, vec![run("s", "a", 1.0, 1.0), run("s", "b", 0.5, 0.99)]),
            (2, vec![run("s", "a", 2.0, 1.0), run("s", "b", 4.0, 1.02)]),
            (3, vec![run("s", "a", 4.0, 1.0), run("s", "b", 1.0, 1.01)]),
        ];
        let text = summary("t", &runs, "a");
        // b: relMSE 0.5, 4, 1 (mean 1.83333, median 1); ratios 0.5, 2, 0.25 (mean 0.91667,
        // median 0.5, 2 of 3 below); relMSE × s mean 3.66667; image means 0.99..1.02.
        assert!(
            text.contains(
                "| s | b | 3 | 1.83333 | 1.00000 | 0.917 | 0.500 | 2 of 3 | 3.6667 | 1.0100 | 0.9900 | 1.0200 |"
            ),
            "{text}"
        );
        assert!(text.contains("| s | a | 3 | 2.33333 | 2.00000 | 1.000 | 1.000 | 0 of 3 |"), "{text}");
        assert!(text.contains("| s | b | 0.50000 | 4.00000 | 1.00000 |"), "{text}");
    }
}
