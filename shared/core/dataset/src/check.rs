//! Reading a dataset back and checking that its parts agree: `info.json`'s totals, the
//! episodes' metadata and the data files' rows.

use std::{
    collections::BTreeMap,
    fs::{self, File},
    path::{Path, PathBuf},
};

use arrow_array::{cast::AsArray, types::Int64Type, RecordBatch};
use parquet::{
    arrow::arrow_reader::ParquetRecordBatchReaderBuilder, file::reader::FileReader,
    file::serialized_reader::SerializedFileReader,
};
use serde_json::Value;

use crate::DatasetError;

/// What a dataset holds, as [`check`] found it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DatasetSummary {
    /// Episodes.
    pub total_episodes: u64,
    /// Frames.
    pub total_frames: u64,
    /// Tasks.
    pub total_tasks: u64,
    /// Data files.
    pub data_files: usize,
}

/// Reads the dataset at `dir` and checks that `info.json`'s totals, `meta/tasks.parquet`, the
/// episodes in `meta/episodes/` (numbered 0, 1, ... with contiguous frame ranges) and the rows of
/// the data files (each file as many rows as the episodes that point at it) agree. The error
/// names the first disagreement and its file.
pub fn check(dir: &Path) -> Result<DatasetSummary, DatasetError> {
    let info_path = dir.join("meta/info.json");
    let text = fs::read_to_string(&info_path).map_err(|e| DatasetError::io(&info_path, e))?;
    let info: Value = serde_json::from_str(&text)
        .map_err(|e| DatasetError::invalid(&info_path, e.to_string()))?;
    let total = |key: &str| {
        info.get(key)
            .and_then(Value::as_u64)
            .ok_or_else(|| DatasetError::invalid(&info_path, format!("no whole `{key}`")))
    };
    let (episodes, frames, tasks) = (
        total("total_episodes")?,
        total("total_frames")?,
        total("total_tasks")?,
    );
    let task_rows = rows_of(&dir.join("meta/tasks.parquet"))?;
    if task_rows != tasks {
        return Err(DatasetError::invalid(
            &info_path,
            format!("total_tasks is {tasks}, meta/tasks.parquet has {task_rows}"),
        ));
    }
    // Per data file (chunk, file): the frames the episodes say it holds.
    let mut claimed: BTreeMap<(i64, i64), u64> = BTreeMap::new();
    let mut next_episode = 0i64;
    let mut next_frame = 0i64;
    for path in parquet_files(&dir.join("meta/episodes"))? {
        for batch in batches(&path)? {
            let col = |name: &str| {
                batch
                    .column_by_name(name)
                    .and_then(|c| c.as_primitive_opt::<Int64Type>())
                    .ok_or_else(|| DatasetError::invalid(&path, format!("no int64 `{name}`")))
            };
            let (index, length, from, to, chunk, file) = (
                col("episode_index")?,
                col("length")?,
                col("dataset_from_index")?,
                col("dataset_to_index")?,
                col("data/chunk_index")?,
                col("data/file_index")?,
            );
            for i in 0..batch.num_rows() {
                let bad = |what: String| DatasetError::invalid(&path, what);
                if index.value(i) != next_episode {
                    return Err(bad(format!(
                        "episode {} where episode {next_episode} was due",
                        index.value(i)
                    )));
                }
                if from.value(i) != next_frame || to.value(i) - from.value(i) != length.value(i) {
                    return Err(bad(format!(
                        "episode {next_episode}: frames {}..{} (length {}) where they start at {next_frame}",
                        from.value(i),
                        to.value(i),
                        length.value(i)
                    )));
                }
                *claimed.entry((chunk.value(i), file.value(i))).or_default() +=
                    length.value(i) as u64;
                next_episode += 1;
                next_frame = to.value(i);
            }
        }
    }
    if next_episode as u64 != episodes || next_frame as u64 != frames {
        return Err(DatasetError::invalid(
            &info_path,
            format!(
                "says {episodes} episodes and {frames} frames, meta/episodes has {next_episode} and {next_frame}"
            ),
        ));
    }
    let data = parquet_files(&dir.join("data"))?;
    let mut found: BTreeMap<(i64, i64), u64> = BTreeMap::new();
    for path in &data {
        let key = chunk_and_file(path)
            .ok_or_else(|| DatasetError::invalid(path, "not named chunk-C/file-F.parquet"))?;
        found.insert(key, rows_of(path)?);
    }
    if found != claimed {
        return Err(DatasetError::invalid(
            &dir.join("data"),
            format!("rows per (chunk, file) {found:?}, the episodes claim {claimed:?}"),
        ));
    }
    Ok(DatasetSummary {
        total_episodes: episodes,
        total_frames: frames,
        total_tasks: tasks,
        data_files: data.len(),
    })
}

/// `dir/chunk-*/file-*.parquet`, sorted (lerobot's `load_nested_dataset` glob).
fn parquet_files(dir: &Path) -> Result<Vec<PathBuf>, DatasetError> {
    let mut out = Vec::new();
    if !dir.exists() {
        return Ok(out);
    }
    for chunk in fs::read_dir(dir).map_err(|e| DatasetError::io(dir, e))? {
        let chunk = chunk.map_err(|e| DatasetError::io(dir, e))?.path();
        if !chunk.is_dir() {
            continue;
        }
        for file in fs::read_dir(&chunk).map_err(|e| DatasetError::io(&chunk, e))? {
            let file = file.map_err(|e| DatasetError::io(&chunk, e))?.path();
            if file.extension().is_some_and(|e| e == "parquet") {
                out.push(file);
            }
        }
    }
    out.sort();
    Ok(out)
}

fn chunk_and_file(path: &Path) -> Option<(i64, i64)> {
    let file = path
        .file_stem()?
        .to_str()?
        .strip_prefix("file-")?
        .parse()
        .ok()?;
    let chunk = path
        .parent()?
        .file_name()?
        .to_str()?
        .strip_prefix("chunk-")?
        .parse()
        .ok()?;
    Some((chunk, file))
}

fn rows_of(path: &Path) -> Result<u64, DatasetError> {
    let file = File::open(path).map_err(|e| DatasetError::io(path, e))?;
    let reader = SerializedFileReader::new(file).map_err(|e| DatasetError::parquet(path, e))?;
    Ok(reader.metadata().file_metadata().num_rows().max(0) as u64)
}

fn batches(path: &Path) -> Result<Vec<RecordBatch>, DatasetError> {
    let file = File::open(path).map_err(|e| DatasetError::io(path, e))?;
    let reader = ParquetRecordBatchReaderBuilder::try_new(file)
        .and_then(|b| b.build())
        .map_err(|e| DatasetError::parquet(path, e))?;
    reader
        .map(|b| b.map_err(|e| DatasetError::parquet(path, e)))
        .collect()
}
