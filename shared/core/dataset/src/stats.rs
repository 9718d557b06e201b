//! Feature statistics as lerobot computes them: per episode, then aggregated over episodes.
//!
//! The method is lerobot's (`src/lerobot/datasets/compute_stats.py`, v3.0 codebase):
//!
//! - Per episode and per dimension ([`FeatureStats::of_episode`]): `min`, `max`, `mean`, `std`
//!   (population: `sqrt(max(0, mean(x²) - mean(x)²))`), `count` (frames), and the quantiles
//!   `q01`, `q10`, `q50`, `q90`, `q99` read off a 5000-bin histogram spanning
//!   `[min - 1e-10, max + 1e-10]` with linear interpolation inside the bin (its
//!   `RunningQuantileStats` fed the whole episode in one batch). An episode of fewer than two
//!   frames gets `std = 0` and every quantile equal to the mean (`_compute_basic_stats`).
//! - Over episodes ([`FeatureStats::aggregate`], `aggregate_feature_stats`): min of mins, max of
//!   maxes, the count-weighted mean, the variance of the union by the parallel formula
//!   (`Σ count·(std² + (mean - total_mean)²) / Σ count`), and for each quantile the smallest of
//!   the episodes' values for `q01`..`q50` and the largest for `q90`, `q99` (lerobot keeps an
//!   envelope, since exact global quantiles cannot be recovered from per-episode ones).
//!
//! We compute in `f64` (lerobot in the column's `float32` where the data is `float32`): values
//! agree to `float32` rounding, not bit for bit.

use serde_json::{Map, Value};

/// The quantiles lerobot computes, with their keys (`DEFAULT_QUANTILES`).
pub const QUANTILES: [(f64, &str); 5] = [
    (0.01, "q01"),
    (0.10, "q10"),
    (0.50, "q50"),
    (0.90, "q90"),
    (0.99, "q99"),
];

/// Histogram bins per dimension for the quantiles (`num_quantile_bins`).
pub const QUANTILE_BINS: usize = 5000;

/// The statistics of one feature, one value per dimension (`count` is one number).
#[derive(Debug, Clone, PartialEq)]
pub struct FeatureStats {
    /// Smallest value.
    pub min: Vec<f64>,
    /// Largest value.
    pub max: Vec<f64>,
    /// Mean.
    pub mean: Vec<f64>,
    /// Population standard deviation.
    pub std: Vec<f64>,
    /// Frames.
    pub count: u64,
    /// Per quantile of [`QUANTILES`], per dimension.
    pub quantiles: [Vec<f64>; 5],
}

impl FeatureStats {
    /// The statistics of an episode's `rows` of `width` values each (`values.len() = rows ×
    /// width`, row-major). `None` for an episode without frames.
    pub fn of_episode(values: &[f64], width: usize) -> Option<Self> {
        if width == 0 || values.is_empty() || !values.len().is_multiple_of(width) {
            return None;
        }
        let rows = values.len() / width;
        let column = |d: usize| values.iter().skip(d).step_by(width).copied();
        let mut stats = FeatureStats {
            min: vec![0.0; width],
            max: vec![0.0; width],
            mean: vec![0.0; width],
            std: vec![0.0; width],
            count: rows as u64,
            quantiles: Default::default(),
        };
        for q in &mut stats.quantiles {
            *q = vec![0.0; width];
        }
        let mut hist = vec![0.0f64; QUANTILE_BINS];
        for d in 0..width {
            let (mut lo, mut hi, mut sum, mut sum_sq) =
                (f64::INFINITY, f64::NEG_INFINITY, 0.0, 0.0);
            for x in column(d) {
                lo = lo.min(x);
                hi = hi.max(x);
                sum += x;
                sum_sq += x * x;
            }
            let n = rows as f64;
            let mean = sum / n;
            stats.min[d] = lo;
            stats.max[d] = hi;
            stats.mean[d] = mean;
            if rows < 2 {
                // `_compute_basic_stats`: np.std of one value, quantiles at the mean.
                for q in &mut stats.quantiles {
                    q[d] = mean;
                }
                continue;
            }
            stats.std[d] = (sum_sq / n - mean * mean).max(0.0).sqrt();
            let first = lo - 1e-10;
            let last = hi + 1e-10;
            hist.iter_mut().for_each(|h| *h = 0.0);
            for x in column(d) {
                hist[bin_of(x, first, last)] += 1.0;
            }
            for (slot, (q, _)) in stats.quantiles.iter_mut().zip(QUANTILES) {
                slot[d] = quantile_of(&hist, first, last, q * n);
            }
        }
        Some(stats)
    }

    /// The statistics of several episodes' together, as lerobot aggregates them. `None` for an
    /// empty list or dimensions that differ.
    pub fn aggregate(parts: &[&FeatureStats]) -> Option<Self> {
        let first = parts.first()?;
        let width = first.mean.len();
        if parts.iter().any(|p| p.mean.len() != width) {
            return None;
        }
        let total: u64 = parts.iter().map(|p| p.count).sum();
        if total == 0 {
            return None;
        }
        let n = total as f64;
        let mut out = FeatureStats {
            min: vec![f64::INFINITY; width],
            max: vec![f64::NEG_INFINITY; width],
            mean: vec![0.0; width],
            std: vec![0.0; width],
            count: total,
            quantiles: Default::default(),
        };
        for (i, q) in out.quantiles.iter_mut().enumerate() {
            *q = if QUANTILES[i].0 <= 0.5 {
                vec![f64::INFINITY; width]
            } else {
                vec![f64::NEG_INFINITY; width]
            };
        }
        for d in 0..width {
            let mean = parts
                .iter()
                .map(|p| p.mean[d] * p.count as f64)
                .sum::<f64>()
                / n;
            let variance = parts
                .iter()
                .map(|p| (p.std[d].powi(2) + (p.mean[d] - mean).powi(2)) * p.count as f64)
                .sum::<f64>()
                / n;
            out.mean[d] = mean;
            out.std[d] = variance.sqrt();
            for p in parts {
                out.min[d] = out.min[d].min(p.min[d]);
                out.max[d] = out.max[d].max(p.max[d]);
                for (i, q) in out.quantiles.iter_mut().enumerate() {
                    q[d] = if QUANTILES[i].0 <= 0.5 {
                        q[d].min(p.quantiles[i][d])
                    } else {
                        q[d].max(p.quantiles[i][d])
                    };
                }
            }
        }
        Some(out)
    }

    /// The statistics by name as `meta/stats.json` and the episodes' `stats/<feature>/<stat>`
    /// columns hold them: `(name, values)`, `count` as a one-element list.
    pub fn named(&self) -> Vec<(&'static str, Vec<f64>)> {
        let mut out = vec![
            ("min", self.min.clone()),
            ("max", self.max.clone()),
            ("mean", self.mean.clone()),
            ("std", self.std.clone()),
            ("count", vec![self.count as f64]),
        ];
        for (i, (_, key)) in QUANTILES.iter().enumerate() {
            out.push((key, self.quantiles[i].clone()));
        }
        out
    }

    /// As a `meta/stats.json` entry.
    pub fn to_json(&self) -> Value {
        let mut map = Map::new();
        for (name, values) in self.named() {
            let value = if name == "count" {
                Value::from(vec![self.count])
            } else {
                Value::from(values)
            };
            map.insert(name.to_string(), value);
        }
        Value::Object(map)
    }

    /// Reads a `meta/stats.json` entry; the error says which statistic is missing or malformed.
    pub fn from_json(value: &Value) -> Result<Self, String> {
        let list = |name: &str| -> Result<Vec<f64>, String> {
            value
                .get(name)
                .and_then(Value::as_array)
                .ok_or_else(|| format!("no `{name}` list"))?
                .iter()
                .map(|v| {
                    v.as_f64()
                        .ok_or_else(|| format!("`{name}` holds a non-number"))
                })
                .collect()
        };
        let count = list("count")?;
        let count = match count[..] {
            [c] if c >= 0.0 && c.fract() == 0.0 => c as u64,
            _ => return Err("`count` is not one whole number".into()),
        };
        let mut quantiles: [Vec<f64>; 5] = Default::default();
        for (i, (_, key)) in QUANTILES.iter().enumerate() {
            quantiles[i] = list(key)?;
        }
        let stats = FeatureStats {
            min: list("min")?,
            max: list("max")?,
            mean: list("mean")?,
            std: list("std")?,
            count,
            quantiles,
        };
        let width = stats.mean.len();
        let same = [&stats.min, &stats.max, &stats.std]
            .into_iter()
            .chain(stats.quantiles.iter())
            .all(|v| v.len() == width);
        if !same {
            return Err("its statistics have different lengths".into());
        }
        Ok(stats)
    }
}

/// The bin of `x` among [`QUANTILE_BINS`] equal bins over `[first, last]`, as `np.histogram`
/// places it (each bin half-open but the last, which holds `last`).
fn bin_of(x: f64, first: f64, last: f64) -> usize {
    let width = (last - first) / QUANTILE_BINS as f64;
    let mut bin = ((x - first) / width).floor();
    if !bin.is_finite() || bin < 0.0 {
        bin = 0.0;
    }
    let mut bin = (bin as usize).min(QUANTILE_BINS - 1);
    // Rounding can put x one bin off its edges (numpy corrects the same way).
    if bin > 0 && x < edge(bin, first, last) {
        bin -= 1;
    } else if bin + 1 < QUANTILE_BINS && x >= edge(bin + 1, first, last) {
        bin += 1;
    }
    bin
}

/// Edge `i` of `np.linspace(first, last, QUANTILE_BINS + 1)`, computed as numpy does
/// (`i × step + start`, the last edge `stop` itself), so that a value falls in the same bin.
fn edge(i: usize, first: f64, last: f64) -> f64 {
    if i == QUANTILE_BINS {
        last
    } else {
        i as f64 * ((last - first) / QUANTILE_BINS as f64) + first
    }
}

/// `RunningQuantileStats._compute_single_quantile`: the first bin whose cumulative count
/// reaches `target`, interpolated linearly inside it.
fn quantile_of(hist: &[f64], first: f64, last: f64, target: f64) -> f64 {
    let mut before = 0.0;
    for (idx, &count) in hist.iter().enumerate() {
        let cumulative = before + count;
        if cumulative >= target {
            if idx == 0 {
                return first;
            }
            if count == 0.0 {
                return edge(idx, first, last);
            }
            let fraction = (target - before) / count;
            let lo = edge(idx, first, last);
            return lo + fraction * (edge(idx + 1, first, last) - lo);
        }
        before = cumulative;
    }
    last
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Direct computation of the quantile the histogram estimates: the sample at which the
    /// cumulative count reaches `q × n` (the histogram then interpolates inside its bin).
    fn sample_quantile(sorted: &[f64], q: f64) -> f64 {
        let target = (q * sorted.len() as f64).ceil() as usize;
        sorted[target.max(1) - 1]
    }

    fn pseudo_random(n: usize, seed: u64) -> Vec<f64> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((s >> 11) as f64 / (1u64 << 53) as f64) * 4.0 - 1.0
            })
            .collect()
    }

    #[test]
    fn episode_stats_match_a_direct_computation() {
        let (rows, width) = (997, 3);
        let a = pseudo_random(rows, 1);
        let b: Vec<f64> = (0..rows).map(|i| (i as f64 * 0.01).sin() * 5.0).collect();
        let values: Vec<f64> = (0..rows).flat_map(|i| [a[i], b[i], 2.5]).collect();
        let stats = FeatureStats::of_episode(&values, width).expect("stats");
        assert_eq!(stats.count, rows as u64);
        for (d, col) in [a, b, vec![2.5; rows]].iter().enumerate() {
            let n = col.len() as f64;
            let mean = col.iter().sum::<f64>() / n;
            let var = col.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
            let mut sorted = col.clone();
            sorted.sort_by(f64::total_cmp);
            assert_eq!(stats.min[d], sorted[0]);
            assert_eq!(stats.max[d], sorted[rows - 1]);
            assert!((stats.mean[d] - mean).abs() < 1e-12, "mean of {d}");
            assert!((stats.std[d] - var.sqrt()).abs() < 1e-9, "std of {d}");
            // The histogram's quantile is within one bin of the sample it stands for.
            let bin = (sorted[rows - 1] - sorted[0] + 2e-10) / QUANTILE_BINS as f64;
            for (i, (q, key)) in QUANTILES.iter().enumerate() {
                let exact = sample_quantile(&sorted, *q);
                let got = stats.quantiles[i][d];
                assert!(
                    (got - exact).abs() <= bin + 1e-9,
                    "{key} of column {d}: {got} vs {exact}"
                );
            }
        }
    }

    #[test]
    fn a_single_frame_has_its_mean_for_every_quantile() {
        let stats = FeatureStats::of_episode(&[1.5, -2.0], 2).expect("stats");
        assert_eq!(stats.std, [0.0, 0.0]);
        assert!(stats.quantiles.iter().all(|q| q == &[1.5, -2.0]));
        assert!(FeatureStats::of_episode(&[], 2).is_none());
    }

    #[test]
    fn aggregation_equals_the_stats_of_the_union_where_lerobot_says_so() {
        let a = pseudo_random(400, 7);
        let b: Vec<f64> = pseudo_random(600, 9)
            .iter()
            .map(|x| x * 3.0 + 1.0)
            .collect();
        let sa = FeatureStats::of_episode(&a, 1).expect("a");
        let sb = FeatureStats::of_episode(&b, 1).expect("b");
        let union: Vec<f64> = a.iter().chain(&b).copied().collect();
        let su = FeatureStats::of_episode(&union, 1).expect("union");
        let agg = FeatureStats::aggregate(&[&sa, &sb]).expect("aggregate");
        assert_eq!(agg.count, 1000);
        assert_eq!(agg.min, su.min);
        assert_eq!(agg.max, su.max);
        assert!((agg.mean[0] - su.mean[0]).abs() < 1e-12);
        assert!((agg.std[0] - su.std[0]).abs() < 1e-9);
        // The quantile envelope: lower quantiles the smaller, upper the larger.
        assert_eq!(
            agg.quantiles[0][0],
            sa.quantiles[0][0].min(sb.quantiles[0][0])
        );
        assert_eq!(
            agg.quantiles[4][0],
            sa.quantiles[4][0].max(sb.quantiles[4][0])
        );
        // And it reads back from its JSON form.
        let back = FeatureStats::from_json(&agg.to_json()).expect("json");
        assert_eq!(back, agg);
    }
}
