//! Writing a LeRobot v3.0 dataset: new, or appended to, and crash-safe either way.
//!
//! The layout (see `docs/lerobot.md` for the facts and their sources):
//!
//! ```text
//! meta/info.json                               codebase_version "v3.0", fps, features, totals, ...
//! meta/stats.json                              per feature: min max mean std count q01..q99
//! meta/tasks.parquet                           task (pandas index) | task_index
//! meta/episodes/chunk-000/file-000.parquet     one row per episode: where its frames are, stats
//! data/chunk-000/file-000.parquet              one row per frame, one row group per episode
//! ```
//!
//! # Crash safety
//!
//! lerobot finds data and episode files by listing their folders, so a file put in place before
//! `info.json` says it belongs would already be read. The writer therefore never changes the
//! dataset in place: it builds the next version in a staging folder beside it (`.<name>.
//! teleop-export-staging`: the existing files hard-linked, which costs no copy, the new and
//! rewritten ones written there), and swaps the two folders in one `renameat2(RENAME_EXCHANGE)`
//! (Linux 3.15, see rename(2)); a new dataset is one `rename`. A reader sees the old dataset or
//! the new one, never a mix. Whatever a crashed export left (the staging folder before the swap,
//! the old version after it) is removed by the next export, which takes a lock file
//! (`.<name>.teleop-export.lock`, an advisory `flock`) so two exports never build at once.
//! Existing files are never written to: they are links shared with the old version.
//!
//! Before the swap the staging folder is read back with [`check`](crate::check) (a version
//! that does not check is never published) and every file and folder in it is synced; after
//! it the parent folder is synced, so that the swap itself survives a power loss.
//!
//! For tests, the environment variable `TELEOP_EXPORT_CRASH_AT` set to `mid-data` (after the
//! first episode's frames are written), `before-swap` or `after-swap` aborts the process there,
//! as a kill or a crash at that moment would.

use std::{
    collections::BTreeMap,
    fs::{self, File},
    io::Write,
    path::{Path, PathBuf},
    sync::Arc,
};

use arrow_array::{
    builder::{ListBuilder, StringBuilder},
    cast::AsArray,
    types::{Float64Type, Int64Type},
    Array, ArrayRef, FixedSizeListArray, Float32Array, Int64Array, ListArray, RecordBatch,
    StringArray,
};
use arrow_schema::{DataType, Field, Schema, SchemaRef};
use parquet::{
    arrow::{arrow_reader::ParquetRecordBatchReaderBuilder, ArrowWriter},
    basic::Compression,
    file::properties::WriterProperties,
};
use serde_json::{json, Map, Value};

use crate::{stats::FeatureStats, DatasetError};

/// The format version this writer writes (`CODEBASE_VERSION`).
pub const CODEBASE_VERSION: &str = "v3.0";
/// Files per chunk folder (`DEFAULT_CHUNK_SIZE`).
pub const CHUNKS_SIZE: u64 = 1000;
/// A data file is closed once it is this big (`DEFAULT_DATA_FILE_SIZE_IN_MB`).
pub const DATA_FILES_SIZE_IN_MB: u64 = 100;
/// Video files' size (`DEFAULT_VIDEO_FILE_SIZE_IN_MB`); this writer writes no videos.
const VIDEO_FILES_SIZE_IN_MB: u64 = 200;
/// `data_path` of `info.json`.
pub const DATA_PATH: &str = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet";
/// The frame columns every dataset has after its features (`DEFAULT_FEATURES`): `timestamp`
/// float32, the rest int64.
pub const DEFAULT_FEATURES: [&str; 5] = [
    "timestamp",
    "frame_index",
    "episode_index",
    "index",
    "task_index",
];

/// A float32 vector feature (`observation.state`, `action`, ...).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FeatureSpec {
    /// Its key in `info.json` and its column's name (no `/`: lerobot refuses it).
    pub key: String,
    /// A name per dimension.
    pub names: Vec<String>,
}

/// What a dataset holds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DatasetSpec {
    /// Frames per second.
    pub fps: u32,
    /// `robot_type` of `info.json`.
    pub robot_type: String,
    /// The vector features, in column order.
    pub features: Vec<FeatureSpec>,
}

impl DatasetSpec {
    /// `info.json`'s `features`: ours, then the default columns.
    fn features_json(&self) -> Value {
        let mut map = Map::new();
        for f in &self.features {
            map.insert(
                f.key.clone(),
                json!({"dtype": "float32", "shape": [f.names.len()], "names": f.names}),
            );
        }
        for key in DEFAULT_FEATURES {
            let dtype = if key == "timestamp" {
                "float32"
            } else {
                "int64"
            };
            map.insert(
                key.to_string(),
                json!({"dtype": dtype, "shape": [1], "names": null}),
            );
        }
        Value::Object(map)
    }

    fn data_schema(&self) -> SchemaRef {
        let mut fields: Vec<Field> = self
            .features
            .iter()
            .map(|f| {
                Field::new(
                    &f.key,
                    DataType::FixedSizeList(
                        Arc::new(Field::new("item", DataType::Float32, true)),
                        f.names.len() as i32,
                    ),
                    false,
                )
            })
            .collect();
        fields.push(Field::new("timestamp", DataType::Float32, false));
        for key in &DEFAULT_FEATURES[1..] {
            fields.push(Field::new(*key, DataType::Int64, false));
        }
        Arc::new(Schema::new(fields))
    }
}

/// The frames of one episode, gathered before it is written (its statistics need them all, as
/// lerobot's do): one flat row-major buffer per feature.
#[derive(Debug, Clone, Default)]
pub struct EpisodeBuffer {
    widths: Vec<usize>,
    values: Vec<Vec<f32>>,
    frames: usize,
}

impl EpisodeBuffer {
    /// An empty buffer for `spec`'s features.
    pub fn new(spec: &DatasetSpec) -> Self {
        Self {
            widths: spec.features.iter().map(|f| f.names.len()).collect(),
            values: vec![Vec::new(); spec.features.len()],
            frames: 0,
        }
    }

    /// Adds a frame: every feature's values in spec order, concatenated (shorter is padded
    /// with NaN).
    pub fn push(&mut self, row: &[f32]) {
        let mut at = 0;
        for (values, &width) in self.values.iter_mut().zip(&self.widths) {
            for i in 0..width {
                values.push(row.get(at + i).copied().unwrap_or(f32::NAN));
            }
            at += width;
        }
        self.frames += 1;
    }

    /// Frames gathered.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// The first value that is not finite (NaN, ±inf), as (feature index, name index, frame):
    /// such a value would be written silently and poison the statistics (a NaN mean).
    pub fn first_non_finite(&self) -> Option<(usize, usize, usize)> {
        self.values
            .iter()
            .zip(&self.widths)
            .enumerate()
            .find_map(|(feature, (values, &width))| {
                let at = values.iter().position(|v| !v.is_finite())?;
                Some((feature, at % width.max(1), at / width.max(1)))
            })
    }

    /// Empties it for the next episode (keeping its memory).
    pub fn clear(&mut self) {
        self.values.iter_mut().for_each(Vec::clear);
        self.frames = 0;
    }
}

/// One episode as written.
#[derive(Debug, Clone, PartialEq)]
pub struct WrittenEpisode {
    /// Its `episode_index` in the dataset.
    pub episode_index: u64,
    /// Frames.
    pub length: u64,
    /// Its task's `task_index`.
    pub task_index: u64,
    /// The global `index` of its first frame.
    pub from_index: u64,
}

/// What the dataset holds after a commit.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Committed {
    /// Episodes in all.
    pub total_episodes: u64,
    /// Frames in all.
    pub total_frames: u64,
    /// Tasks in all.
    pub total_tasks: u64,
    /// Episodes this export added.
    pub added_episodes: u64,
}

/// One row of `meta/episodes`.
struct EpisodeRow {
    episode_index: u64,
    task: String,
    length: u64,
    data_chunk: u64,
    data_file: u64,
    from: u64,
    stats: Vec<(String, FeatureStats)>,
}

/// Writes episodes into a staging copy of the dataset and swaps it in on [`commit`](Self::commit).
/// Dropped without a commit, it removes its staging folder: the dataset stays as it was.
pub struct DatasetWriter {
    out: PathBuf,
    staging: PathBuf,
    _lock: File,
    spec: DatasetSpec,
    schema: SchemaRef,
    info: Map<String, Value>,
    tasks: Vec<String>,
    stats: BTreeMap<String, FeatureStats>,
    total_episodes: u64,
    total_frames: u64,
    /// The data file being written: its (chunk, file) and writer.
    data: Option<((u64, u64), ArrowWriter<File>)>,
    next_data: (u64, u64),
    next_episodes: (u64, u64),
    rows: Vec<EpisodeRow>,
    existed: bool,
    committed: bool,
}

impl DatasetWriter {
    /// Opens `out` for writing: a new dataset of `spec` if `out` does not exist (or is an empty
    /// folder), else the dataset there, which must have the same fps and features (refused
    /// naming the difference). Removes what a crashed export left.
    pub fn open(out: &Path, spec: DatasetSpec) -> Result<Self, DatasetError> {
        if spec.fps == 0 {
            return Err(DatasetError::invalid(out, "fps must be at least 1"));
        }
        if let Some(f) = spec.features.iter().find(|f| f.key.contains('/')) {
            return Err(DatasetError::invalid(
                out,
                format!(
                    "feature `{}`: lerobot refuses `/` in a feature's key",
                    f.key
                ),
            ));
        }
        let (lock_path, staging) = side_paths(out)?;
        let lock = File::options()
            .create(true)
            .truncate(false)
            .write(true)
            .open(&lock_path)
            .map_err(|e| DatasetError::io(&lock_path, e))?;
        match lock.try_lock() {
            Ok(()) => {}
            Err(fs::TryLockError::WouldBlock) => {
                return Err(DatasetError::invalid(
                    out,
                    format!(
                        "another export is writing this dataset (lock {})",
                        lock_path.display()
                    ),
                ))
            }
            Err(fs::TryLockError::Error(e)) => return Err(DatasetError::io(&lock_path, e)),
        }
        // A crashed export's leftovers: the staging folder (before the swap) or the old version
        // (after it). Neither is the dataset.
        if staging.exists() {
            fs::remove_dir_all(&staging).map_err(|e| DatasetError::io(&staging, e))?;
        }
        let info_path = out.join("meta/info.json");
        let existed = info_path.exists();
        if !existed && out.exists() {
            let mut entries = fs::read_dir(out).map_err(|e| DatasetError::io(out, e))?;
            if entries.next().is_some() {
                return Err(DatasetError::invalid(
                    out,
                    "exists, is not empty and has no meta/info.json: not a dataset to append to",
                ));
            }
        }
        fs::create_dir_all(&staging).map_err(|e| DatasetError::io(&staging, e))?;
        let mut writer = Self {
            out: out.to_path_buf(),
            staging,
            _lock: lock,
            schema: spec.data_schema(),
            info: Map::new(),
            tasks: Vec::new(),
            stats: BTreeMap::new(),
            total_episodes: 0,
            total_frames: 0,
            data: None,
            next_data: (0, 0),
            next_episodes: (0, 0),
            rows: Vec::new(),
            existed,
            committed: false,
            spec,
        };
        if existed {
            writer.load_existing()?;
        } else {
            writer.info = new_info(&writer.spec);
        }
        Ok(writer)
    }

    /// Reads the existing dataset's info, tasks and stats, checks it matches the spec, and links
    /// its files into the staging folder.
    fn load_existing(&mut self) -> Result<(), DatasetError> {
        let info_path = self.out.join("meta/info.json");
        let text = fs::read_to_string(&info_path).map_err(|e| DatasetError::io(&info_path, e))?;
        let info: Value = serde_json::from_str(&text)
            .map_err(|e| DatasetError::invalid(&info_path, e.to_string()))?;
        let Value::Object(info) = info else {
            return Err(DatasetError::invalid(&info_path, "not a JSON object"));
        };
        let version = info.get("codebase_version").and_then(Value::as_str);
        if version != Some(CODEBASE_VERSION) {
            return Err(DatasetError::invalid(
                &info_path,
                format!(
                    "codebase_version is {version:?}: only {CODEBASE_VERSION} datasets are appended to"
                ),
            ));
        }
        check_same(&info_path, &info, &self.spec)?;
        let count = |key: &str| -> Result<u64, DatasetError> {
            info.get(key).and_then(Value::as_u64).ok_or_else(|| {
                DatasetError::invalid(&info_path, format!("`{key}` is not a whole number"))
            })
        };
        self.total_episodes = count("total_episodes")?;
        self.total_frames = count("total_frames")?;
        if self.total_episodes > 0 {
            self.tasks = read_tasks(&self.out.join("meta/tasks.parquet"))?;
            let stats_path = self.out.join("meta/stats.json");
            let text =
                fs::read_to_string(&stats_path).map_err(|e| DatasetError::io(&stats_path, e))?;
            let stats: Value = serde_json::from_str(&text)
                .map_err(|e| DatasetError::invalid(&stats_path, e.to_string()))?;
            let Value::Object(stats) = stats else {
                return Err(DatasetError::invalid(&stats_path, "not a JSON object"));
            };
            for (key, value) in &stats {
                let s = FeatureStats::from_json(value)
                    .map_err(|e| DatasetError::invalid(&stats_path, format!("`{key}`: {e}")))?;
                self.stats.insert(key.clone(), s);
            }
        }
        self.info = info;
        self.next_data = next_file(&self.out.join("data"))?;
        self.next_episodes = next_file(&self.out.join("meta/episodes"))?;
        link_tree(
            &self.out,
            &self.staging,
            &[
                Path::new("meta/info.json"),
                Path::new("meta/stats.json"),
                Path::new("meta/tasks.parquet"),
            ],
        )
    }

    /// The dataset's spec.
    pub fn spec(&self) -> &DatasetSpec {
        &self.spec
    }

    /// Writes one episode of task `task` (into the staging copy; nothing is visible before
    /// [`commit`](Self::commit)). An episode without frames, or with a value that is not finite
    /// ([`EpisodeBuffer::first_non_finite`]), is refused.
    pub fn write_episode(
        &mut self,
        task: &str,
        episode: &EpisodeBuffer,
    ) -> Result<WrittenEpisode, DatasetError> {
        let length = episode.frames as u64;
        if length == 0 {
            return Err(DatasetError::invalid(
                &self.out,
                "an episode without frames",
            ));
        }
        if let Some((f, name, frame)) = episode.first_non_finite() {
            let f = &self.spec.features[f];
            return Err(DatasetError::invalid(
                &self.out,
                format!(
                    "feature `{}`, `{}`: a value that is not finite at frame {frame}",
                    f.key, f.names[name]
                ),
            ));
        }
        let task_index = match self.tasks.iter().position(|t| t == task) {
            Some(i) => i as u64,
            None => {
                self.tasks.push(task.to_string());
                (self.tasks.len() - 1) as u64
            }
        };
        let episode_index = self.total_episodes;
        let from = self.total_frames;
        let fps = f64::from(self.spec.fps);
        let timestamps: Vec<f32> = (0..length).map(|k| (k as f64 / fps) as f32).collect();
        let frame_index: Vec<i64> = (0..length as i64).collect();
        let index: Vec<i64> = (from as i64..(from + length) as i64).collect();

        let mut columns: Vec<ArrayRef> = Vec::with_capacity(self.schema.fields().len());
        let mut stats = Vec::with_capacity(columns.capacity());
        for (f, values) in self.spec.features.iter().zip(&episode.values) {
            let width = f.names.len();
            let item = Arc::new(Field::new("item", DataType::Float32, true));
            let array = FixedSizeListArray::try_new(
                item,
                width as i32,
                Arc::new(Float32Array::from(values.clone())),
                None,
            )
            .map_err(|e| DatasetError::invalid(&self.out, format!("feature `{}`: {e}", f.key)))?;
            columns.push(Arc::new(array));
            let wide: Vec<f64> = values.iter().map(|&v| f64::from(v)).collect();
            if let Some(s) = FeatureStats::of_episode(&wide, width) {
                stats.push((f.key.clone(), s));
            }
        }
        let constant = |v: u64| vec![v as i64; length as usize];
        let defaults: [(&str, Vec<f64>, ArrayRef); 5] = [
            (
                "timestamp",
                timestamps.iter().map(|&t| f64::from(t)).collect(),
                Arc::new(Float32Array::from(timestamps.clone())),
            ),
            (
                "frame_index",
                frame_index.iter().map(|&v| v as f64).collect(),
                Arc::new(Int64Array::from(frame_index.clone())),
            ),
            (
                "episode_index",
                vec![episode_index as f64; length as usize],
                Arc::new(Int64Array::from(constant(episode_index))),
            ),
            (
                "index",
                index.iter().map(|&v| v as f64).collect(),
                Arc::new(Int64Array::from(index.clone())),
            ),
            (
                "task_index",
                vec![task_index as f64; length as usize],
                Arc::new(Int64Array::from(constant(task_index))),
            ),
        ];
        for (key, wide, array) in defaults {
            columns.push(array);
            if let Some(s) = FeatureStats::of_episode(&wide, 1) {
                stats.push((key.to_string(), s));
            }
        }
        let batch = RecordBatch::try_new(self.schema.clone(), columns)
            .map_err(|e| DatasetError::invalid(&self.out, e.to_string()))?;

        let (chunk, file) = self.data_file()?;
        let path = self.staging.join(chunk_file("data", chunk, file));
        let Some((_, writer)) = self.data.as_mut() else {
            return Err(DatasetError::invalid(&path, "no data file open"));
        };
        writer
            .write(&batch)
            .and_then(|()| writer.flush())
            .map_err(|e| DatasetError::parquet(&path, e))?;
        crash_point("mid-data");

        self.rows.push(EpisodeRow {
            episode_index,
            task: task.to_string(),
            length,
            data_chunk: chunk,
            data_file: file,
            from,
            stats,
        });
        self.total_episodes += 1;
        self.total_frames += length;
        Ok(WrittenEpisode {
            episode_index,
            length,
            task_index,
            from_index: from,
        })
    }

    /// The data file to write the next episode into: the open one until it passes
    /// [`DATA_FILES_SIZE_IN_MB`], then the next.
    fn data_file(&mut self) -> Result<(u64, u64), DatasetError> {
        if let Some(((chunk, file), writer)) = &self.data {
            if (writer.bytes_written() as u64) < DATA_FILES_SIZE_IN_MB * 1024 * 1024 {
                return Ok((*chunk, *file));
            }
        }
        self.close_data()?;
        let (chunk, file) = self.next_data;
        self.next_data = following(chunk, file);
        let path = self.staging.join(chunk_file("data", chunk, file));
        let writer = parquet_writer(&path, self.schema.clone())?;
        self.data = Some(((chunk, file), writer));
        Ok((chunk, file))
    }

    fn close_data(&mut self) -> Result<(), DatasetError> {
        if let Some(((chunk, file), writer)) = self.data.take() {
            let path = self.staging.join(chunk_file("data", chunk, file));
            finish_parquet(&path, writer)?;
        }
        Ok(())
    }

    /// Writes the metadata and swaps the staging copy in: from here on readers see the new
    /// episodes. With no episode written, leaves the dataset as it was.
    pub fn commit(mut self) -> Result<Committed, DatasetError> {
        let added = self.rows.len() as u64;
        if added == 0 {
            return Ok(self.totals(0));
        }
        self.close_data()?;
        self.write_episodes_meta()?;
        write_tasks(&self.staging.join("meta/tasks.parquet"), &self.tasks)?;
        self.write_stats()?;
        self.info
            .insert("total_episodes".into(), self.total_episodes.into());
        self.info
            .insert("total_frames".into(), self.total_frames.into());
        self.info
            .insert("total_tasks".into(), (self.tasks.len() as u64).into());
        self.info.insert(
            "splits".into(),
            json!({"train": format!("0:{}", self.total_episodes)}),
        );
        write_json(
            &self.staging.join("meta/info.json"),
            &Value::Object(self.info.clone()),
        )?;
        // A version whose parts disagree is never published (dropped, the staging folder goes).
        crate::check(&self.staging)?;
        sync_folders(&self.staging)?;
        crash_point("before-swap");
        swap_in(&self.staging, &self.out, self.existed)?;
        self.committed = true;
        crash_point("after-swap");
        // After the swap the staging path holds the old version (or nothing).
        if self.staging.exists() {
            fs::remove_dir_all(&self.staging).map_err(|e| DatasetError::io(&self.staging, e))?;
        }
        Ok(self.totals(added))
    }

    fn totals(&self, added: u64) -> Committed {
        Committed {
            total_episodes: self.total_episodes,
            total_frames: self.total_frames,
            total_tasks: self.tasks.len() as u64,
            added_episodes: added,
        }
    }

    fn write_stats(&mut self) -> Result<(), DatasetError> {
        let mut keys: Vec<String> = self.spec.features.iter().map(|f| f.key.clone()).collect();
        keys.extend(DEFAULT_FEATURES.iter().map(|k| k.to_string()));
        let mut out = Map::new();
        for key in keys {
            let mut parts: Vec<&FeatureStats> = self.stats.get(&key).into_iter().collect();
            parts.extend(
                self.rows
                    .iter()
                    .flat_map(|r| &r.stats)
                    .filter(|(k, _)| *k == key)
                    .map(|(_, s)| s),
            );
            let path = self.staging.join("meta/stats.json");
            let total = FeatureStats::aggregate(&parts).ok_or_else(|| {
                DatasetError::invalid(
                    &path,
                    format!("feature `{key}`: the existing statistics have another width"),
                )
            })?;
            out.insert(key, total.to_json());
        }
        write_json(&self.staging.join("meta/stats.json"), &Value::Object(out))
    }

    /// `meta/episodes/chunk-C/file-F.parquet` for this export's episodes.
    fn write_episodes_meta(&mut self) -> Result<(), DatasetError> {
        let (chunk, file) = self.next_episodes;
        let path = self.staging.join(chunk_file("meta/episodes", chunk, file));
        let int = |f: &dyn Fn(&EpisodeRow) -> u64| -> ArrayRef {
            Arc::new(Int64Array::from_iter_values(
                self.rows.iter().map(|r| f(r) as i64),
            ))
        };
        let mut fields = vec![
            Field::new("episode_index", DataType::Int64, false),
            Field::new(
                "tasks",
                DataType::List(Arc::new(Field::new("item", DataType::Utf8, true))),
                false,
            ),
            Field::new("length", DataType::Int64, false),
            Field::new("data/chunk_index", DataType::Int64, false),
            Field::new("data/file_index", DataType::Int64, false),
            Field::new("dataset_from_index", DataType::Int64, false),
            Field::new("dataset_to_index", DataType::Int64, false),
        ];
        let mut tasks = ListBuilder::new(StringBuilder::new());
        for r in &self.rows {
            tasks.values().append_value(&r.task);
            tasks.append(true);
        }
        let mut columns: Vec<ArrayRef> = vec![
            int(&|r| r.episode_index),
            Arc::new(tasks.finish()),
            int(&|r| r.length),
            int(&|r| r.data_chunk),
            int(&|r| r.data_file),
            int(&|r| r.from),
            int(&|r| r.from + r.length),
        ];
        // `stats/<feature>/<stat>`, every row's statistics in the same order.
        let Some(first) = self.rows.first() else {
            return Ok(());
        };
        for (i, (key, s)) in first.stats.iter().enumerate() {
            for (j, (stat, _)) in s.named().iter().enumerate() {
                let name = format!("stats/{key}/{stat}");
                if *stat == "count" {
                    fields.push(Field::new(
                        &name,
                        DataType::List(Arc::new(Field::new("item", DataType::Int64, true))),
                        false,
                    ));
                    columns.push(Arc::new(ListArray::from_iter_primitive::<Int64Type, _, _>(
                        self.rows
                            .iter()
                            .map(|r| Some(vec![Some(r.stats[i].1.count as i64)])),
                    )));
                } else {
                    fields.push(Field::new(
                        &name,
                        DataType::List(Arc::new(Field::new("item", DataType::Float64, true))),
                        false,
                    ));
                    columns.push(Arc::new(
                        ListArray::from_iter_primitive::<Float64Type, _, _>(self.rows.iter().map(
                            |r| {
                                Some(
                                    r.stats[i].1.named()[j]
                                        .1
                                        .iter()
                                        .map(|&v| Some(v))
                                        .collect::<Vec<_>>(),
                                )
                            },
                        )),
                    ));
                }
            }
        }
        fields.push(Field::new(
            "meta/episodes/chunk_index",
            DataType::Int64,
            false,
        ));
        fields.push(Field::new(
            "meta/episodes/file_index",
            DataType::Int64,
            false,
        ));
        columns.push(int(&|_| chunk));
        columns.push(int(&|_| file));
        let schema = Arc::new(Schema::new(fields));
        let batch = RecordBatch::try_new(schema.clone(), columns)
            .map_err(|e| DatasetError::invalid(&path, e.to_string()))?;
        let mut writer = parquet_writer(&path, schema)?;
        writer
            .write(&batch)
            .map_err(|e| DatasetError::parquet(&path, e))?;
        finish_parquet(&path, writer)
    }
}

#[cfg(test)]
impl DatasetWriter {
    /// What a killed export leaves: its staging folder, and its lock released (the kernel drops
    /// a dead process's `flock`).
    fn die(mut self) {
        self.committed = true;
    }
}

impl Drop for DatasetWriter {
    fn drop(&mut self) {
        if !self.committed {
            // Best effort: what is left is removed by the next export anyway.
            let _ = fs::remove_dir_all(&self.staging);
        }
    }
}

/// The lock file and the staging folder beside `out`.
fn side_paths(out: &Path) -> Result<(PathBuf, PathBuf), DatasetError> {
    let name = out
        .file_name()
        .and_then(|n| n.to_str())
        .ok_or_else(|| DatasetError::invalid(out, "the dataset's folder needs a UTF-8 name"))?;
    let parent = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if !parent.is_dir() {
        return Err(DatasetError::invalid(
            out,
            format!("its parent folder {} does not exist", parent.display()),
        ));
    }
    Ok((
        parent.join(format!(".{name}.teleop-export.lock")),
        parent.join(format!(".{name}.teleop-export-staging")),
    ))
}

/// A new dataset's `info.json`, totals zero.
fn new_info(spec: &DatasetSpec) -> Map<String, Value> {
    let info = json!({
        "codebase_version": CODEBASE_VERSION,
        "robot_type": spec.robot_type,
        "total_episodes": 0,
        "total_frames": 0,
        "total_tasks": 0,
        "chunks_size": CHUNKS_SIZE,
        "data_files_size_in_mb": DATA_FILES_SIZE_IN_MB,
        "video_files_size_in_mb": VIDEO_FILES_SIZE_IN_MB,
        "fps": spec.fps,
        "splits": {},
        "data_path": DATA_PATH,
        "video_path": null,
        "features": spec.features_json(),
    });
    match info {
        Value::Object(map) => map,
        _ => Map::new(),
    }
}

/// The existing dataset has `spec`'s fps and features, or an error naming the first difference.
fn check_same(
    path: &Path,
    info: &Map<String, Value>,
    spec: &DatasetSpec,
) -> Result<(), DatasetError> {
    let fps = info.get("fps").and_then(Value::as_u64);
    if fps != Some(u64::from(spec.fps)) {
        return Err(DatasetError::mismatch(
            path,
            format!("the dataset is at {fps:?} fps, this export at {}", spec.fps),
        ));
    }
    let Some(Value::Object(have)) = info.get("features") else {
        return Err(DatasetError::invalid(path, "no `features` object"));
    };
    let Value::Object(want) = spec.features_json() else {
        return Ok(());
    };
    for key in have.keys() {
        if !want.contains_key(key) {
            return Err(DatasetError::mismatch(
                path,
                format!("the dataset has feature `{key}`, this export does not"),
            ));
        }
    }
    for (key, w) in &want {
        let Some(h) = have.get(key) else {
            return Err(DatasetError::mismatch(
                path,
                format!("this export has feature `{key}`, the dataset does not"),
            ));
        };
        for field in ["dtype", "shape"] {
            if h.get(field) != w.get(field) {
                return Err(DatasetError::mismatch(
                    path,
                    format!(
                        "feature `{key}`: {field} {} in the dataset, {} in this export",
                        h.get(field).unwrap_or(&Value::Null),
                        w.get(field).unwrap_or(&Value::Null)
                    ),
                ));
            }
        }
        let names = |v: &Value| -> Vec<String> {
            v.get("names")
                .and_then(Value::as_array)
                .map(|a| {
                    a.iter()
                        .map(|n| n.as_str().unwrap_or("").to_string())
                        .collect()
                })
                .unwrap_or_default()
        };
        let (hn, wn) = (names(h), names(w));
        if let Some(i) = (0..hn.len().max(wn.len())).find(|&i| hn.get(i) != wn.get(i)) {
            return Err(DatasetError::mismatch(
                path,
                format!(
                    "feature `{key}`: name {i} is `{}` in the dataset, `{}` in this export",
                    hn.get(i).map_or("(none)", String::as_str),
                    wn.get(i).map_or("(none)", String::as_str)
                ),
            ));
        }
    }
    Ok(())
}

/// `<dir>/chunk-CCC/file-FFF.parquet`.
fn chunk_file(dir: &str, chunk: u64, file: u64) -> String {
    format!("{dir}/chunk-{chunk:03}/file-{file:03}.parquet")
}

/// The file after `(chunk, file)` (`update_chunk_file_indices`).
fn following(chunk: u64, file: u64) -> (u64, u64) {
    if file + 1 >= CHUNKS_SIZE {
        (chunk + 1, 0)
    } else {
        (chunk, file + 1)
    }
}

/// The (chunk, file) after the last `chunk-*/file-*.parquet` under `dir` ((0, 0) for none).
fn next_file(dir: &Path) -> Result<(u64, u64), DatasetError> {
    let mut last: Option<(u64, u64)> = None;
    if !dir.exists() {
        return Ok((0, 0));
    }
    for chunk in fs::read_dir(dir).map_err(|e| DatasetError::io(dir, e))? {
        let chunk = chunk.map_err(|e| DatasetError::io(dir, e))?;
        let Some(c) = number_in(&chunk.file_name().to_string_lossy(), "chunk-", "") else {
            continue;
        };
        let chunk_dir = chunk.path();
        for file in fs::read_dir(&chunk_dir).map_err(|e| DatasetError::io(&chunk_dir, e))? {
            let file = file.map_err(|e| DatasetError::io(&chunk_dir, e))?;
            if let Some(f) = number_in(&file.file_name().to_string_lossy(), "file-", ".parquet") {
                last = last.max(Some((c, f)));
            }
        }
    }
    Ok(last.map_or((0, 0), |(c, f)| following(c, f)))
}

fn number_in(name: &str, prefix: &str, suffix: &str) -> Option<u64> {
    name.strip_prefix(prefix)?
        .strip_suffix(suffix)?
        .parse()
        .ok()
}

/// Hard-links every file under `from` into `to` (same relative paths), but `skip`.
fn link_tree(from: &Path, to: &Path, skip: &[&Path]) -> Result<(), DatasetError> {
    let mut stack = vec![PathBuf::new()];
    while let Some(rel) = stack.pop() {
        let dir = from.join(&rel);
        fs::create_dir_all(to.join(&rel)).map_err(|e| DatasetError::io(to.join(&rel), e))?;
        for entry in fs::read_dir(&dir).map_err(|e| DatasetError::io(&dir, e))? {
            let entry = entry.map_err(|e| DatasetError::io(&dir, e))?;
            let rel = rel.join(entry.file_name());
            let kind = entry
                .file_type()
                .map_err(|e| DatasetError::io(entry.path(), e))?;
            if kind.is_dir() {
                stack.push(rel);
            } else if !skip.contains(&rel.as_path()) {
                fs::hard_link(entry.path(), to.join(&rel))
                    .map_err(|e| DatasetError::io(entry.path(), e))?;
            }
        }
    }
    Ok(())
}

/// Aborts the process at the crash point `name` when `TELEOP_EXPORT_CRASH_AT` names it (tests of
/// crash safety: see the module's documentation). No destructor runs, as under a kill.
fn crash_point(name: &str) {
    if std::env::var_os("TELEOP_EXPORT_CRASH_AT").is_some_and(|at| at == name) {
        eprintln!("TELEOP_EXPORT_CRASH_AT={name}: aborting");
        std::process::abort();
    }
}

/// Syncs `dir` and every folder under it (their entries: the new files' names), so that what
/// the swap publishes is on disk (files are synced as they are finished).
fn sync_folders(dir: &Path) -> Result<(), DatasetError> {
    let mut stack = vec![dir.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in fs::read_dir(&dir).map_err(|e| DatasetError::io(&dir, e))? {
            let entry = entry.map_err(|e| DatasetError::io(&dir, e))?;
            if entry
                .file_type()
                .map_err(|e| DatasetError::io(entry.path(), e))?
                .is_dir()
            {
                stack.push(entry.path());
            }
        }
        File::open(&dir)
            .and_then(|d| d.sync_all())
            .map_err(|e| DatasetError::io(&dir, e))?;
    }
    Ok(())
}

/// Puts `staging` at `out`: one exchange of the two folders when `out` is a dataset, one rename
/// otherwise (onto nothing or onto an empty folder).
fn swap_in(staging: &Path, out: &Path, existed: bool) -> Result<(), DatasetError> {
    if existed {
        exchange(staging, out)?;
    } else {
        fs::rename(staging, out).map_err(|e| DatasetError::io(out, e))?;
    }
    let parent = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    File::open(parent)
        .and_then(|d| d.sync_all())
        .map_err(|e| DatasetError::io(parent, e))
}

/// Swaps two folders atomically (`renameat2(RENAME_EXCHANGE)`).
fn exchange(a: &Path, b: &Path) -> Result<(), DatasetError> {
    use std::os::unix::ffi::OsStrExt;
    let c = |p: &Path| {
        std::ffi::CString::new(p.as_os_str().as_bytes())
            .map_err(|_| DatasetError::invalid(p, "a path with a NUL byte"))
    };
    let (ca, cb) = (c(a)?, c(b)?);
    // SAFETY: two valid NUL-terminated paths that outlive the call; no memory is shared.
    let rc = unsafe {
        libc::renameat2(
            libc::AT_FDCWD,
            ca.as_ptr(),
            libc::AT_FDCWD,
            cb.as_ptr(),
            libc::RENAME_EXCHANGE,
        )
    };
    if rc == 0 {
        Ok(())
    } else {
        Err(DatasetError::io(b, std::io::Error::last_os_error()))
    }
}

fn parquet_writer(path: &Path, schema: SchemaRef) -> Result<ArrowWriter<File>, DatasetError> {
    if let Some(dir) = path.parent() {
        fs::create_dir_all(dir).map_err(|e| DatasetError::io(dir, e))?;
    }
    let file = File::create(path).map_err(|e| DatasetError::io(path, e))?;
    // Snappy, as lerobot writes its files.
    let props = WriterProperties::builder()
        .set_compression(Compression::SNAPPY)
        .build();
    ArrowWriter::try_new(file, schema, Some(props)).map_err(|e| DatasetError::parquet(path, e))
}

fn finish_parquet(path: &Path, mut writer: ArrowWriter<File>) -> Result<(), DatasetError> {
    writer
        .finish()
        .map_err(|e| DatasetError::parquet(path, e))?;
    writer
        .inner_mut()
        .sync_all()
        .map_err(|e| DatasetError::io(path, e))
}

fn write_json(path: &Path, value: &Value) -> Result<(), DatasetError> {
    if let Some(dir) = path.parent() {
        fs::create_dir_all(dir).map_err(|e| DatasetError::io(dir, e))?;
    }
    let text = serde_json::to_string_pretty(value)
        .map_err(|e| DatasetError::invalid(path, e.to_string()))?;
    let mut file = File::create(path).map_err(|e| DatasetError::io(path, e))?;
    file.write_all(text.as_bytes())
        .and_then(|()| file.write_all(b"\n"))
        .and_then(|()| file.sync_all())
        .map_err(|e| DatasetError::io(path, e))
}

/// `meta/tasks.parquet` as pandas writes a frame indexed by `task` (`write_tasks`): the
/// `task_index` column, the `task` index column, and the `pandas` schema metadata that makes
/// `pd.read_parquet` restore `task` as the index (lerobot looks tasks up by it).
fn write_tasks(path: &Path, tasks: &[String]) -> Result<(), DatasetError> {
    let pandas = json!({
        "index_columns": ["task"],
        "column_indexes": [{"name": null, "field_name": null, "pandas_type": "unicode",
                            "numpy_type": "object", "metadata": {"encoding": "UTF-8"}}],
        "columns": [
            {"name": "task_index", "field_name": "task_index", "pandas_type": "int64",
             "numpy_type": "int64", "metadata": null},
            {"name": "task", "field_name": "task", "pandas_type": "unicode",
             "numpy_type": "object", "metadata": null},
        ],
        "creator": {"library": "teleop-dataset", "version": env!("CARGO_PKG_VERSION")},
        "pandas_version": "2.2.3",
    });
    let schema = Arc::new(
        Schema::new(vec![
            Field::new("task_index", DataType::Int64, false),
            Field::new("task", DataType::Utf8, false),
        ])
        .with_metadata([("pandas".to_string(), pandas.to_string())].into()),
    );
    let batch = RecordBatch::try_new(
        schema.clone(),
        vec![
            Arc::new(Int64Array::from_iter_values(0..tasks.len() as i64)),
            Arc::new(StringArray::from_iter_values(tasks)),
        ],
    )
    .map_err(|e| DatasetError::invalid(path, e.to_string()))?;
    let mut writer = parquet_writer(path, schema)?;
    writer
        .write(&batch)
        .map_err(|e| DatasetError::parquet(path, e))?;
    finish_parquet(path, writer)
}

/// The tasks of `meta/tasks.parquet`, ordered by `task_index` (which must be 0..n).
fn read_tasks(path: &Path) -> Result<Vec<String>, DatasetError> {
    let file = File::open(path).map_err(|e| DatasetError::io(path, e))?;
    let reader = ParquetRecordBatchReaderBuilder::try_new(file)
        .and_then(|b| b.build())
        .map_err(|e| DatasetError::parquet(path, e))?;
    let mut by_index = BTreeMap::new();
    for batch in reader {
        let batch = batch.map_err(|e| DatasetError::invalid(path, e.to_string()))?;
        let task = batch.column_by_name("task");
        let index = batch.column_by_name("task_index");
        let (Some(task), Some(index)) = (task, index) else {
            return Err(DatasetError::invalid(
                path,
                "no `task` and `task_index` columns",
            ));
        };
        let index = index
            .as_primitive_opt::<Int64Type>()
            .ok_or_else(|| DatasetError::invalid(path, "`task_index` is not int64"))?;
        let texts: Vec<Option<&str>> = if let Some(s) = task.as_string_opt::<i32>() {
            s.iter().collect()
        } else if let Some(s) = task.as_string_opt::<i64>() {
            s.iter().collect()
        } else {
            return Err(DatasetError::invalid(path, "`task` is not a string column"));
        };
        for (i, text) in texts.into_iter().enumerate() {
            if index.is_null(i) {
                return Err(DatasetError::invalid(path, "a null task_index"));
            }
            by_index.insert(index.value(i), text.unwrap_or("").to_string());
        }
    }
    let expected: Vec<i64> = (0..by_index.len() as i64).collect();
    if by_index.keys().copied().collect::<Vec<_>>() != expected {
        return Err(DatasetError::invalid(
            path,
            "task_index is not 0, 1, 2, ...",
        ));
    }
    Ok(by_index.into_values().collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::check;

    fn spec() -> DatasetSpec {
        DatasetSpec {
            fps: 10,
            robot_type: "revo2".into(),
            features: vec![
                FeatureSpec {
                    key: "observation.state".into(),
                    names: vec!["a".into(), "b".into()],
                },
                FeatureSpec {
                    key: "action".into(),
                    names: vec!["c".into()],
                },
            ],
        }
    }

    fn episode(frames: usize, base: f32) -> EpisodeBuffer {
        let mut e = EpisodeBuffer::new(&spec());
        for k in 0..frames {
            let x = base + k as f32;
            e.push(&[x, -x, 2.0 * x]);
        }
        e
    }

    fn info(dir: &Path) -> Value {
        let text = fs::read_to_string(dir.join("meta/info.json")).expect("info.json");
        serde_json::from_str(&text).expect("json")
    }

    /// The `index` column of every data file, in file order.
    fn indexes(dir: &Path) -> Vec<i64> {
        let mut files: Vec<PathBuf> = Vec::new();
        for chunk in fs::read_dir(dir.join("data")).expect("data") {
            for f in fs::read_dir(chunk.expect("chunk").path()).expect("chunk") {
                files.push(f.expect("file").path());
            }
        }
        files.sort();
        let mut out = Vec::new();
        for f in files {
            let reader = ParquetRecordBatchReaderBuilder::try_new(File::open(f).expect("open"))
                .and_then(|b| b.build())
                .expect("reader");
            for batch in reader {
                let batch = batch.expect("batch");
                let col = batch.column_by_name("index").expect("index");
                out.extend(col.as_primitive::<Int64Type>().values().iter().copied());
            }
        }
        out
    }

    #[test]
    fn a_new_dataset_then_an_append_read_back_consistently() {
        let tmp = tempfile::tempdir().expect("tmp");
        let out = tmp.path().join("ds");
        let mut w = DatasetWriter::open(&out, spec()).expect("open");
        let e0 = w.write_episode("pick", &episode(5, 0.0)).expect("e0");
        let e1 = w.write_episode("place", &episode(3, 10.0)).expect("e1");
        assert_eq!((e0.episode_index, e0.from_index, e0.task_index), (0, 0, 0));
        assert_eq!((e1.episode_index, e1.from_index, e1.task_index), (1, 5, 1));
        let done = w.commit().expect("commit");
        assert_eq!(
            (done.total_episodes, done.total_frames, done.total_tasks),
            (2, 8, 2)
        );
        let summary = check(&out).expect("check");
        assert_eq!(summary.total_frames, 8);
        assert_eq!(info(&out)["splits"]["train"], "0:2");
        assert_eq!(
            info(&out)["features"]["observation.state"]["shape"],
            json!([2])
        );

        // Append: a known task keeps its index, a new one gets the next; a new data file.
        let mut w = DatasetWriter::open(&out, spec()).expect("reopen");
        let e2 = w.write_episode("place", &episode(4, 20.0)).expect("e2");
        let e3 = w.write_episode("pour", &episode(2, 30.0)).expect("e3");
        assert_eq!((e2.episode_index, e2.from_index, e2.task_index), (2, 8, 1));
        assert_eq!(e3.task_index, 2);
        w.commit().expect("commit");
        let summary = check(&out).expect("check");
        assert_eq!(
            (
                summary.total_episodes,
                summary.total_frames,
                summary.data_files
            ),
            (4, 14, 2)
        );
        assert_eq!(indexes(&out), (0..14).collect::<Vec<_>>());
        assert_eq!(
            read_tasks(&out.join("meta/tasks.parquet")).expect("tasks"),
            ["pick", "place", "pour"]
        );
        // The global stats cover every frame: action = 2x, x over 0..4, 10..12, 20..23, 30..31.
        let stats: Value =
            serde_json::from_str(&fs::read_to_string(out.join("meta/stats.json")).expect("stats"))
                .expect("json");
        assert_eq!(stats["action"]["count"], json!([14]));
        assert_eq!(stats["action"]["max"], json!([62.0]));
        assert_eq!(stats["index"]["max"], json!([13.0]));
        let xs: Vec<f64> = [0..5, 10..13, 20..24, 30..32]
            .into_iter()
            .flatten()
            .map(|x| 2.0 * x as f64)
            .collect();
        let mean = xs.iter().sum::<f64>() / 14.0;
        let got = stats["action"]["mean"][0].as_f64().expect("mean");
        assert!((got - mean).abs() < 1e-9, "{got} vs {mean}");
    }

    #[test]
    fn appending_other_features_is_refused_by_name() {
        let tmp = tempfile::tempdir().expect("tmp");
        let out = tmp.path().join("ds");
        let mut w = DatasetWriter::open(&out, spec()).expect("open");
        w.write_episode("pick", &episode(2, 0.0)).expect("e0");
        w.commit().expect("commit");
        let mut other = spec();
        other.features[0].names[1] = "z".into();
        let err = DatasetWriter::open(&out, other)
            .err()
            .expect("refused")
            .to_string();
        assert!(
            err.contains("observation.state") && err.contains("`b`") && err.contains("`z`"),
            "{err}"
        );
        let mut other = spec();
        other.fps = 30;
        let err = DatasetWriter::open(&out, other)
            .err()
            .expect("refused")
            .to_string();
        assert!(err.contains("fps"), "{err}");
        // Refusals leave the dataset as it was.
        assert_eq!(check(&out).expect("check").total_episodes, 1);
    }

    /// Writes a dataset of one 5-frame episode at `out`; returns its `meta/info.json`.
    fn one_episode_dataset(out: &Path) -> Vec<u8> {
        let mut w = DatasetWriter::open(out, spec()).expect("open");
        w.write_episode("pick", &episode(5, 0.0)).expect("e0");
        w.commit().expect("commit");
        fs::read(out.join("meta/info.json")).expect("info")
    }

    #[test]
    fn a_crashed_export_leaves_the_dataset_readable_and_is_cleaned_up() {
        let tmp = tempfile::tempdir().expect("tmp");
        let out = tmp.path().join("ds");
        let before = one_episode_dataset(&out);

        // An export that dies after writing frames, before its commit (no destructor runs).
        let mut w = DatasetWriter::open(&out, spec()).expect("reopen");
        w.write_episode("pick", &episode(7, 1.0)).expect("e1");
        w.write_episode("new task", &episode(3, 1.0)).expect("e2");
        let staging = w.staging.clone();
        w.die();
        assert!(staging.join("data/chunk-000/file-001.parquet").exists());
        // The dataset is untouched: same info, files agree, no new data file in it.
        assert_eq!(fs::read(out.join("meta/info.json")).expect("info"), before);
        assert_eq!(check(&out).expect("check").total_frames, 5);
        assert!(!out.join("data/chunk-000/file-001.parquet").exists());

        // The next export cleans up and appends as if nothing had happened. (Crashes mid-data,
        // just before and just after the swap, in a real process: tests/tests/export.rs with
        // TELEOP_EXPORT_CRASH_AT.)
        let mut w = DatasetWriter::open(&out, spec()).expect("after the crash");
        assert!(!staging.join("data/chunk-000/file-001.parquet").exists());
        w.write_episode("pick", &episode(2, 1.0)).expect("e1");
        w.commit().expect("commit");
        assert!(!staging.exists());
        let summary = check(&out).expect("check");
        assert_eq!(
            (
                summary.total_episodes,
                summary.total_frames,
                summary.total_tasks
            ),
            (2, 7, 1)
        );
        assert_eq!(indexes(&out), (0..7).collect::<Vec<_>>());
    }

    #[test]
    fn an_episode_with_a_value_that_is_not_finite_is_refused_by_name() {
        let tmp = tempfile::tempdir().expect("tmp");
        let out = tmp.path().join("ds");
        let mut e = episode(3, 0.0);
        assert_eq!(e.first_non_finite(), None);
        e.push(&[1.0, 2.0, f32::NAN]);
        assert_eq!(e.first_non_finite(), Some((1, 0, 3)));
        let mut w = DatasetWriter::open(&out, spec()).expect("open");
        let err = w
            .write_episode("pick", &e)
            .expect_err("refused")
            .to_string();
        assert!(
            err.contains("`action`, `c`") && err.contains("frame 3"),
            "{err}"
        );
        let mut e = episode(2, 0.0);
        e.push(&[1.0, f32::INFINITY, 0.0]);
        assert_eq!(e.first_non_finite(), Some((0, 1, 2)));
    }

    #[test]
    fn a_version_that_does_not_check_is_not_published() {
        let tmp = tempfile::tempdir().expect("tmp");
        let out = tmp.path().join("ds");
        let before = one_episode_dataset(&out);
        // A stray data file in the staging folder: its rows belong to no episode.
        let mut w = DatasetWriter::open(&out, spec()).expect("reopen");
        w.write_episode("pick", &episode(2, 1.0)).expect("e1");
        let stray = w.staging.join("data/chunk-000/file-007.parquet");
        fs::copy(out.join("data/chunk-000/file-000.parquet"), &stray).expect("copy");
        let staging = w.staging.clone();
        let err = w.commit().expect_err("refused").to_string();
        assert!(err.contains("rows per (chunk, file)"), "{err}");
        assert_eq!(fs::read(out.join("meta/info.json")).expect("info"), before);
        assert_eq!(check(&out).expect("check").total_frames, 5);
        assert!(!staging.exists(), "the failed version is removed");
    }

    #[test]
    fn a_folder_that_is_no_dataset_is_not_written_into() {
        let tmp = tempfile::tempdir().expect("tmp");
        fs::write(tmp.path().join("notes.txt"), "mine").expect("write");
        let err = DatasetWriter::open(tmp.path(), spec())
            .err()
            .expect("refused")
            .to_string();
        assert!(err.contains("no meta/info.json"), "{err}");
        // An empty folder is fine.
        let empty = tmp.path().join("empty");
        fs::create_dir(&empty).expect("mkdir");
        let mut w = DatasetWriter::open(&empty, spec()).expect("empty folder");
        w.write_episode("pick", &episode(1, 0.0)).expect("e0");
        w.commit().expect("commit");
        assert_eq!(check(&empty).expect("check").total_frames, 1);
    }
}
