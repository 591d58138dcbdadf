//! Where a keyframe's time goes, as `loops --json` reports it under `stages`: the CLI's own
//! decode (and `--resize`) and the library's stages ([`topoloc::profile`]), per keyframe.

use crate::process::median_and_p90;
use serde_json::{json, Map, Value};
use std::time::Duration;
use topoloc::profile::{Stage, StageTimes};

/// Per-keyframe times of every stage, milliseconds.
#[derive(Default)]
pub struct StageLog {
    decode: Vec<f64>,
    stages: Vec<StageTimes>,
    keyframe: Vec<f64>,
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

impl StageLog {
    /// One keyframe: its decode time, the library's stage times for it, and the time from
    /// describing to the detector's answer (`keyframe_ms`, without decode).
    pub fn record(&mut self, decode: Duration, stages: StageTimes, keyframe_ms: f64) {
        self.decode.push(ms(decode));
        self.stages.push(stages);
        self.keyframe.push(keyframe_ms);
    }

    /// `{stage: {median_ms, mean_ms, p90_ms, calls_mean}}` for `decode`, every library stage,
    /// and `other` (the keyframe time no stage covers: the database, the gates, copies), plus
    /// `keyframe_with_decode_ms_median`.
    pub fn to_json(&self) -> Value {
        let n = self.keyframe.len().max(1) as f64;
        let summary = |values: &[f64], calls: f64| {
            let (median, p90) = median_and_p90(values);
            json!({
                "median_ms": median,
                "mean_ms": values.iter().sum::<f64>() / n,
                "p90_ms": p90,
                "calls_mean": calls / n,
            })
        };
        let mut out = Map::new();
        out.insert(
            "decode".into(),
            summary(&self.decode, self.decode.len() as f64),
        );
        for stage in Stage::ALL {
            let values: Vec<f64> = self.stages.iter().map(|s| ms(s.get(stage))).collect();
            let calls: f64 = self.stages.iter().map(|s| f64::from(s.calls(stage))).sum();
            out.insert(stage.name().into(), summary(&values, calls));
        }
        let other: Vec<f64> = self
            .stages
            .iter()
            .zip(&self.keyframe)
            .map(|(s, &k)| (k - ms(s.total())).max(0.0))
            .collect();
        out.insert("other".into(), summary(&other, self.keyframe.len() as f64));
        let with_decode: Vec<f64> = self
            .decode
            .iter()
            .zip(&self.keyframe)
            .map(|(d, k)| d + k)
            .collect();
        out.insert(
            "keyframe_with_decode_ms_median".into(),
            json!(median_and_p90(&with_decode).0),
        );
        Value::Object(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stage_summaries_cover_every_stage_and_the_rest() {
        let mut log = StageLog::default();
        for k in 1..=3u32 {
            let _ = topoloc::profile::take();
            topoloc::profile::add(Stage::Matching, Duration::from_millis(u64::from(k)));
            topoloc::profile::add(Stage::Matching, Duration::from_millis(1));
            let stages = topoloc::profile::take();
            log.record(Duration::from_millis(2), stages, 10.0);
        }
        let json = log.to_json();
        assert_eq!(json["matching"]["median_ms"], 3.0);
        assert_eq!(json["matching"]["calls_mean"], 2.0);
        assert_eq!(json["cnn"]["mean_ms"], 0.0);
        assert_eq!(json["decode"]["median_ms"], 2.0);
        // 10 ms per keyframe, of which matching took 2, 3 and 4.
        assert_eq!(json["other"]["median_ms"], 7.0);
        assert_eq!(json["keyframe_with_decode_ms_median"], 12.0);
    }
}
