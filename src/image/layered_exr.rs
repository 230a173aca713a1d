//! The layered EXR a render writes: which channels, where each takes its values, and how the
//! pixels reach the file. A one-process render streams them (`StreamedExr`): each finished tile
//! is made into the file's channels and compressed by the thread that rendered it
//! (`TileChunks`), and only the reduced preview stays in memory, so memory no longer grows by
//! 200 bytes a pixel and the compression no longer follows the last tile. Under mpirun the
//! workers encode their tiles and the master only writes the chunks (`EncodedTile`). A frame
//! held whole (`--denoise`, which needs every pixel's neighbours) is encoded on every core at
//! the end (`write_whole`). Either way the file is tiled, the render's own tiles in random
//! order, and appears under its name only once finished.

use super::cryptomatte::{RANKS, Ranks};
use super::data::{Aov, PixelData};
use super::framebuffer::{FrameBuffer, Layer, PixelValue};
use super::output::{self, CRYPTO_MATERIAL, CRYPTO_OBJECT, ExrCompression, StagedFile};
use super::preview::{LogLuminance, PreviewBuffer, rgbe};
use super::region::Region;
use super::window::PixelWindow;
use crate::sys::exr_chunks::{ChunkFile, ExrTiling, TileEncoder};
use crate::sys::image_io::{self, ChannelName, ExrStream, Window};
use crate::sys::unnamed_file::UnnamedFile;
use crate::tiles::{Tile, store_tile};
use glam::Vec3;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// Where a channel of the file takes its values from, pixel by pixel. Data layers and
/// Cryptomatte stay 32-bit float whatever `--half` says (a half float cannot hold an ID's bits,
/// nor a far depth or a world position to the precision a compositor needs).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Source {
    Composite(usize),
    Alpha,
    /// A light layer and its component.
    Light(Layer, usize),
    /// A layer made after the render (a denoised one), by its place in `extra_layers`.
    Extra(usize, usize),
    Records,
    Albedo(usize),
    Normal(usize),
    Depth,
    Position(usize),
    /// A Cryptomatte type's rank: its ID's bits or its coverage.
    Crypto {
        object: bool,
        rank: usize,
        id: bool,
    },
}

impl Source {
    fn full_float(self) -> bool {
        !matches!(
            self,
            Source::Composite(_) | Source::Alpha | Source::Light(..) | Source::Extra(..) | Source::Records
        )
    }

    fn value(self, frame: &FrameBuffer, extra: &[&[Vec3]], i: usize) -> f32 {
        let data = |i: usize| -> &PixelData { &frame.data()[i] };
        match self {
            Source::Composite(c) => frame.composite_at(i)[c],
            Source::Alpha => 1.0,
            Source::Light(layer, c) => frame.layer(layer)[i][c],
            Source::Extra(k, c) => extra[k][i][c],
            Source::Records => frame.records()[i],
            Source::Albedo(c) => data(i).albedo[c],
            Source::Normal(c) => data(i).normal[c],
            Source::Depth => data(i).depth,
            Source::Position(c) => data(i).position[c],
            Source::Crypto { object, rank, id } => {
                let ranks: &Ranks = if object { &data(i).object } else { &data(i).material };
                let entry = ranks[rank];
                if id { f32::from_bits(entry.id) } else { entry.coverage }
            }
        }
    }
}

const RGB: [&str; 3] = ["R", "G", "B"];
const XYZ: [&str; 3] = ["X", "Y", "Z"];

/// The channels of the file, in order, and where each takes its values.
#[derive(Clone, Debug, PartialEq)]
pub struct ChannelPlan {
    channels: Vec<(String, Source)>,
}

impl ChannelPlan {
    /// The composite as R G B A, each light layer as `layer.R/G/B`, each of `extra_layers` (the
    /// denoised ones) the same way, the records layer when asked, and the data layers of `aovs`.
    pub fn new(layers: &[Layer], extra_layers: &[&str], records_layer: bool, aovs: &[Aov]) -> ChannelPlan {
        let mut channels = three("", RGB, Source::Composite);
        channels.push(("A".to_string(), Source::Alpha));
        for &l in layers {
            channels.extend(three(l.name(), RGB, |c| Source::Light(l, c)));
        }
        for (k, name) in extra_layers.iter().enumerate() {
            channels.extend(three(name, RGB, |c| Source::Extra(k, c)));
        }
        if records_layer {
            channels.push(("ic_records.Y".to_string(), Source::Records));
        }
        channels.extend(data_channels(aovs));
        ChannelPlan { channels }
    }

    /// Whether the file counts the records made at each pixel (`--ic-records`).
    pub fn counts_records(&self) -> bool {
        self.channels.iter().any(|(_, source)| *source == Source::Records)
    }

    fn names(&self) -> Vec<ChannelName<'_>> {
        self.channels
            .iter()
            .map(|(name, source)| ChannelName {
                name,
                full_float: source.full_float(),
            })
            .collect()
    }

    fn extra_layers(&self) -> usize {
        self.channels
            .iter()
            .filter_map(|(_, s)| match s {
                Source::Extra(k, _) => Some(k + 1),
                _ => None,
            })
            .max()
            .unwrap_or(0)
    }

    /// The values of `frame`'s pixel `i`, channel by channel, into `out`.
    fn fill(&self, frame: &FrameBuffer, extra: &[&[Vec3]], i: usize, out: &mut [f32]) {
        for (value, (_, source)) in out.iter_mut().zip(&self.channels) {
            *value = source.value(frame, extra, i);
        }
    }
}

/// A three-channel layer's channels, `layer.R` ... (or `R` ... for the unnamed layer), each
/// taking its values from `source` of its component.
fn three(layer: &str, names: [&str; 3], source: impl Fn(usize) -> Source) -> Vec<(String, Source)> {
    (0..3)
        .map(|c| match layer {
            "" => (names[c].to_string(), source(c)),
            _ => (format!("{layer}.{}", names[c]), source(c)),
        })
        .collect()
}

/// The channels of the data layers in `aovs`, in that order.
fn data_channels(aovs: &[Aov]) -> Vec<(String, Source)> {
    let crypto = |layer: &str, object: bool| {
        let mut out = Vec::new();
        for level in 0..RANKS / 2 {
            for (c, channel) in ["R", "G", "B", "A"].iter().enumerate() {
                let source = Source::Crypto {
                    object,
                    rank: 2 * level + c / 2,
                    id: c % 2 == 0,
                };
                out.push((format!("{layer}{level:02}.{channel}"), source));
            }
        }
        out
    };
    let mut channels = Vec::new();
    for aov in aovs {
        match aov {
            Aov::Albedo => channels.extend(three("albedo", RGB, Source::Albedo)),
            Aov::Normal => channels.extend(three("normal", XYZ, Source::Normal)),
            Aov::Depth => channels.push(("depth.Z".to_string(), Source::Depth)),
            Aov::Position => channels.extend(three("position", XYZ, Source::Position)),
            Aov::CryptoObject => channels.extend(crypto(CRYPTO_OBJECT, true)),
            Aov::CryptoMaterial => channels.extend(crypto(CRYPTO_MATERIAL, false)),
        }
    }
    channels
}

/// How the file is laid out: its channels, the pixels it holds, the tile size (the render's
/// own, so that a render tile is a file tile), the sample format and the codec.
#[derive(Clone, Debug)]
pub struct ExrLayout {
    pub plan: ChannelPlan,
    pub window: PixelWindow,
    pub tile: (u32, u32),
    pub half_float: bool,
    pub compression: ExrCompression,
    /// Bytes kept in the streamed file's header for the attributes known only at the end (the
    /// statistics): enough, and the file is finished in place; too few, and it is copied.
    pub header_room: usize,
}

impl ExrLayout {
    /// The file's layout for OpenEXR: its windows, channels (half but for the full-float ones
    /// under `--half`), codec and tiles.
    fn tiling(&self) -> ExrTiling {
        ExrTiling {
            width: self.window.width(),
            height: self.window.height(),
            x: self.window.area.x0,
            y: self.window.area.y0,
            full_width: self.window.full_width,
            full_height: self.window.full_height,
            channels: self
                .plan
                .names()
                .iter()
                .map(|c| (c.name.to_string(), self.half_float && !c.full_float))
                .collect(),
            compression: self.compression.name().to_string(),
            tile: self.tile,
        }
    }

    /// `area` of the full image in the file's coordinates (0 is the window's first row and
    /// column).
    fn in_file(&self, area: Region) -> Region {
        let (ox, oy) = (self.window.area.x0, self.window.area.y0);
        Region {
            x0: area.x0 - ox,
            y0: area.y0 - oy,
            x1: area.x1 - ox,
            y1: area.y1 - oy,
        }
    }

    /// The file tiles `rendered` (in the file's coordinates) reaches into, cut at the edge.
    fn file_tiles_under(&self, rendered: Region) -> Vec<Region> {
        let (tw, th) = self.tile;
        let (w, h) = (self.window.width(), self.window.height());
        let mut out = Vec::new();
        for ty in rendered.y0 / th..rendered.y1.div_ceil(th) {
            for tx in rendered.x0 / tw..rendered.x1.div_ceil(tw) {
                out.push(Region {
                    x0: tx * tw,
                    y0: ty * th,
                    x1: ((tx + 1) * tw).min(w),
                    y1: ((ty + 1) * th).min(h),
                });
            }
        }
        out
    }

    /// A file tile's column and row in the tile grid.
    fn grid(&self, file_tile: Region) -> (u32, u32) {
        (file_tile.x0 / self.tile.0, file_tile.y0 / self.tile.1)
    }

    /// Writes the channels of `frame`'s pixels in `overlap` (the rendered tile `rendered` met
    /// with `file_tile`) into `values`, the file tile's interleaved pixels.
    fn fill(&self, frame: &FrameBuffer, rendered: Region, file_tile: Region, overlap: Region, values: &mut [f32]) {
        self.fill_with(frame, &[], rendered, file_tile, overlap, values);
    }

    /// `fill`, with `extra` layers made after the render (the denoised ones) beside the frame's.
    fn fill_with(
        &self,
        frame: &FrameBuffer,
        extra: &[&[Vec3]],
        rendered: Region,
        file_tile: Region,
        overlap: Region,
        values: &mut [f32],
    ) {
        let n = self.plan.channels.len();
        for y in overlap.y0..overlap.y1 {
            for x in overlap.x0..overlap.x1 {
                let i = ((y - rendered.y0) * rendered.width() + (x - rendered.x0)) as usize;
                let at = ((y - file_tile.y0) * file_tile.width() + (x - file_tile.x0)) as usize * n;
                self.plan.fill(frame, extra, i, &mut values[at..at + n]);
            }
        }
    }

    /// The interleaved values of `file_tile`, which `rendered` (`frame`'s pixels) covers whole.
    fn tile_values(&self, frame: &FrameBuffer, rendered: Region, file_tile: Region) -> Vec<f32> {
        let mut values = vec![0.0; file_tile.pixels() * self.plan.channels.len()];
        self.fill(frame, rendered, file_tile, file_tile, &mut values);
        values
    }

    /// A finished render tile's pixels as a frame of their own, and where they lie in the file.
    fn held(&self, tile: &Tile, values: &[PixelValue]) -> (FrameBuffer, Region) {
        let held = PixelWindow::new(
            Region {
                x0: tile.x0,
                y0: tile.y0,
                x1: tile.x1,
                y1: tile.y1,
            },
            self.window.full_width,
            self.window.full_height,
        );
        let mut frame = FrameBuffer::windowed(held);
        store_tile(&mut frame, tile, values);
        (frame, self.in_file(held.area))
    }

    /// Whether `file_tiles` cover `rendered` whole (it lies on the file's tile grid).
    fn covered_whole(rendered: Region, file_tiles: &[Region]) -> bool {
        file_tiles.iter().all(|t| rendered.meet(*t) == *t)
    }
}

/// A rendered tile as the file stores it, made where it was rendered: the compressed chunks of
/// the file tiles it covers, and its pixels for the preview. Under mpirun this is what a worker
/// sends the master, which only writes it: about a fifth of the bytes of the pixels' values, and
/// no compression on the master's one core.
#[derive(Clone, Debug, PartialEq)]
pub struct EncodedTile {
    /// Each file tile's place in the tile grid and its chunk.
    pub chunks: Vec<((u32, u32), Vec<u8>)>,
    /// The composite of the tile's pixels (row by row) as the preview keeps it.
    pub preview: Vec<[u8; 4]>,
    /// The log luminance of the tile's exact pixels, for the preview's exposure.
    pub log: LogLuminance,
}

/// Encodes rendered tiles into the chunks of a file laid out as `layout`, from any thread.
pub struct TileChunks {
    layout: ExrLayout,
    encoder: TileEncoder,
}

impl TileChunks {
    pub fn new(layout: ExrLayout) -> Result<TileChunks, String> {
        let encoder = TileEncoder::new(&layout.tiling())?;
        Ok(TileChunks { layout, encoder })
    }

    /// The tile as the file stores it; None when it covers file tiles only in part (a region
    /// whose corner is off the tile grid), which only the file's holder can assemble.
    pub fn encode(&self, tile: &Tile, values: &[PixelValue]) -> Result<Option<EncodedTile>, String> {
        let (frame, rendered) = self.layout.held(tile, values);
        let file_tiles = self.layout.file_tiles_under(rendered);
        if !ExrLayout::covered_whole(rendered, &file_tiles) {
            return Ok(None);
        }
        let mut chunks = Vec::with_capacity(file_tiles.len());
        for file_tile in file_tiles {
            chunks.push((self.layout.grid(file_tile), self.chunk(&frame, rendered, file_tile)?));
        }
        let mut log = LogLuminance::default();
        let preview = (0..frame.window().pixels())
            .map(|i| {
                let rgb = frame.composite_at(i);
                log.add(rgb);
                rgbe(rgb)
            })
            .collect();
        Ok(Some(EncodedTile { chunks, preview, log }))
    }

    /// The compressed chunk of `file_tile`, which `rendered` (`frame`'s pixels) covers whole.
    fn chunk(&self, frame: &FrameBuffer, rendered: Region, file_tile: Region) -> Result<Vec<u8>, String> {
        let values = self.layout.tile_values(frame, rendered, file_tile);
        self.encoder.encode(self.layout.grid(file_tile), &values)
    }
}

/// The file the stream writes into until it is finished: without a name where the file system
/// allows (a killed render leaves nothing), else a hidden name beside the target, removed on drop.
enum Scratch {
    Unnamed(Option<UnnamedFile>),
    Named(Option<PathBuf>),
}

impl Scratch {
    fn beside(target: &Path) -> Scratch {
        let dir = target.parent().unwrap_or(Path::new(""));
        match UnnamedFile::create_in(dir) {
            Ok(file) => Scratch::Unnamed(Some(file)),
            Err(_) => {
                let name = target
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_else(|| "output".into());
                Scratch::Named(Some(
                    target.with_file_name(format!(".{name}.stream-{}", std::process::id())),
                ))
            }
        }
    }

    fn path(&self) -> PathBuf {
        match self {
            Scratch::Unnamed(Some(file)) => file.path(),
            Scratch::Named(Some(path)) => path.clone(),
            _ => PathBuf::new(),
        }
    }

    /// The finished file, to be put in place under `target`.
    fn into_staged(mut self, target: &Path) -> StagedFile {
        match &mut self {
            Scratch::Unnamed(file) => StagedFile::unnamed(file.take().expect("the scratch file"), target),
            Scratch::Named(path) => StagedFile::named(path.take().expect("the scratch file"), target),
        }
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if let Scratch::Named(Some(path)) = self {
            let _ = std::fs::remove_file(path);
        }
    }
}

/// A file tile some of whose pixels have come (a region whose corner is off the render's tile
/// grid: a render tile then covers parts of up to four file tiles).
struct PartTile {
    values: Vec<f32>,
    missing: usize,
}

/// The file the tiles go into: encoded by the tile's own thread and written as chunks
/// (`sys::exr_chunks`), or, for a codec OpenEXR's core library cannot encode (DWA before
/// OpenEXR 3.2), through OpenImageIO, which compresses a tile as it writes it.
enum TileFile {
    Chunks { encoder: TileEncoder, file: ChunkFile },
    Stream(ExrStream),
}

impl TileFile {
    fn open(path: &Path, layout: &ExrLayout) -> Result<TileFile, String> {
        let tiling = layout.tiling();
        match TileEncoder::new(&tiling) {
            Ok(encoder) => Ok(TileFile::Chunks {
                encoder,
                file: ChunkFile::open(path, &tiling, layout.header_room)?,
            }),
            Err(_) => Ok(TileFile::Stream(ExrStream::open(
                path,
                tiling.width,
                tiling.height,
                Window {
                    x: tiling.x,
                    y: tiling.y,
                    full_width: tiling.full_width,
                    full_height: tiling.full_height,
                },
                &layout.plan.names(),
                layout.half_float,
                layout.compression.name(),
                layout.tile,
                layout.header_room,
            )?)),
        }
    }

    /// Writes `file_tile` (in the file's coordinates) from its interleaved values.
    fn write_values(&self, layout: &ExrLayout, file_tile: Region, values: &[f32]) -> Result<(), String> {
        match self {
            TileFile::Chunks { encoder, file } => {
                let grid = layout.grid(file_tile);
                file.write(grid, &encoder.encode(grid, values)?)
            }
            TileFile::Stream(stream) => {
                stream.write((file_tile.x0, file_tile.y0), (file_tile.x1, file_tile.y1), values)
            }
        }
    }

    /// Writes a tile's chunk encoded elsewhere (`TileChunks`).
    fn write_chunk(&self, grid: (u32, u32), bytes: &[u8]) -> Result<(), String> {
        match self {
            TileFile::Chunks { file, .. } => file.write(grid, bytes),
            TileFile::Stream(_) => Err("an encoded tile for a file its codec's library writes itself".to_string()),
        }
    }

    fn end(self) -> Result<(), String> {
        match self {
            TileFile::Chunks { file, .. } => file.end(),
            TileFile::Stream(stream) => stream.end(),
        }
    }
}

/// A layered EXR written as the render's tiles finish, and the preview's reduced copy.
pub struct StreamedExr {
    layout: ExrLayout,
    target: PathBuf,
    // Declared before the scratch file: dropped (closed) first.
    file: TileFile,
    scratch: Scratch,
    parts: Mutex<HashMap<(u32, u32), PartTile>>,
    preview: Option<Mutex<PreviewBuffer>>,
    /// The first write that failed: the render stops, and `finish` reports it.
    failure: Mutex<Option<String>>,
}

impl StreamedExr {
    /// Opens the stream for `target` (written by `finish`); with `preview`, keeps the reduced
    /// copy the preview is made from.
    pub fn open(target: &Path, layout: ExrLayout, preview: bool) -> Result<StreamedExr, String> {
        let scratch = Scratch::beside(target);
        let file = TileFile::open(&scratch.path(), &layout).map_err(|e| output::explain_failure(target, e))?;
        let (w, h) = (layout.window.width(), layout.window.height());
        Ok(StreamedExr {
            preview: preview.then(|| Mutex::new(PreviewBuffer::new(w, h))),
            layout,
            target: target.to_path_buf(),
            file,
            scratch,
            parts: Mutex::new(HashMap::new()),
            failure: Mutex::new(None),
        })
    }

    /// Whether a write failed (the render had better stop: the file cannot be finished).
    pub fn failed(&self) -> bool {
        self.failure.lock().unwrap_or_else(|e| e.into_inner()).is_some()
    }

    /// Makes a finished render tile's pixels into the file's channels and writes the file tiles
    /// it completes. A failure is kept for `finish` (see `failed`).
    pub fn store(&self, tile: &Tile, values: &[PixelValue]) {
        self.keep_failure(|| self.try_store(tile, values));
    }

    /// Writes a tile encoded where it was rendered (`TileChunks::encode`). A failure is kept
    /// for `finish`.
    pub fn store_encoded(&self, tile: &Tile, encoded: &EncodedTile) {
        self.keep_failure(|| self.try_store_encoded(tile, encoded));
    }

    /// Runs `write` unless a write failed before; keeps its failure, the first one, for `finish`.
    fn keep_failure(&self, write: impl FnOnce() -> Result<(), String>) {
        if self.failed() {
            return;
        }
        if let Err(e) = write() {
            let mut first = self.failure.lock().unwrap_or_else(|e| e.into_inner());
            first.get_or_insert_with(|| output::explain_failure(&self.target, e));
        }
    }

    pub fn layout(&self) -> &ExrLayout {
        &self.layout
    }

    fn try_store(&self, tile: &Tile, values: &[PixelValue]) -> Result<(), String> {
        let (frame, rendered) = self.layout().held(tile, values);
        self.keep_for_preview(&frame);
        for file_tile in self.layout.file_tiles_under(rendered) {
            let overlap = rendered.meet(file_tile);
            let values = if overlap == file_tile {
                self.layout.tile_values(&frame, rendered, file_tile)
            } else {
                let Some(values) = self.add_part(&frame, rendered, file_tile, overlap) else {
                    continue;
                };
                values
            };
            self.file.write_values(&self.layout, file_tile, &values)?;
        }
        Ok(())
    }

    fn try_store_encoded(&self, tile: &Tile, encoded: &EncodedTile) -> Result<(), String> {
        let (w, h) = (tile.x1 - tile.x0, tile.y1 - tile.y0);
        if encoded.preview.len() != (w * h) as usize {
            return Err(format!(
                "an encoded tile of {} pixels for a {w}x{h} tile",
                encoded.preview.len()
            ));
        }
        for (grid, bytes) in &encoded.chunks {
            self.file.write_chunk(*grid, bytes)?;
        }
        if let Some(preview) = &self.preview {
            let mut preview = preview.lock().unwrap_or_else(|e| e.into_inner());
            let window = self.layout().window;
            let positions = (tile.y0..tile.y1).flat_map(|y| (tile.x0..tile.x1).map(move |x| (x, y)));
            for (kept, (x, y)) in encoded.preview.iter().zip(positions) {
                if let Some(at) = window.index(x, y) {
                    preview.put(at, *kept);
                }
            }
            preview.add_log(encoded.log);
        }
        Ok(())
    }

    /// Keeps the tile's composite in the preview's reduced copy.
    fn keep_for_preview(&self, frame: &FrameBuffer) {
        let Some(preview) = &self.preview else {
            return;
        };
        let mut preview = preview.lock().unwrap_or_else(|e| e.into_inner());
        let held = frame.window();
        for i in 0..held.pixels() {
            let (x, y) = held.position(i);
            if let Some(at) = self.layout().window.index(x, y) {
                preview.set(at, frame.composite_at(i));
            }
        }
    }

    /// Adds the part `overlap` of a file tile the rendered tile covers only in part; returns the
    /// file tile's pixels once every part has come.
    fn add_part(&self, frame: &FrameBuffer, rendered: Region, file_tile: Region, overlap: Region) -> Option<Vec<f32>> {
        let key = (file_tile.x0, file_tile.y0);
        let mut parts = self.parts.lock().unwrap_or_else(|e| e.into_inner());
        let part = parts.entry(key).or_insert_with(|| PartTile {
            values: vec![0.0; file_tile.pixels() * self.layout.plan.channels.len()],
            missing: file_tile.pixels(),
        });
        self.layout.fill(frame, rendered, file_tile, overlap, &mut part.values);
        part.missing -= overlap.pixels();
        if part.missing > 0 {
            return None;
        }
        parts.remove(&key).map(|p| p.values)
    }

    /// The reduced copy the preview is made from, once every tile is in (None without a
    /// preview); taken, so that the preview can be made while `finish` writes the file.
    pub fn take_preview(&self) -> Option<PreviewBuffer> {
        let preview = self.preview.as_ref()?;
        let mut kept = preview.lock().unwrap_or_else(|e| e.into_inner());
        Some(std::mem::replace(&mut *kept, PreviewBuffer::new(0, 0)))
    }

    /// Writes the file, staged beside its target with `attributes` in its header (the
    /// statistics, known only now); it is not in place yet.
    pub fn finish(self, attributes: &[(String, String)]) -> Result<StagedFile, String> {
        if let Some(e) = self.failure.into_inner().unwrap_or_else(|e| e.into_inner()) {
            return Err(e);
        }
        let parts = self.parts.into_inner().unwrap_or_else(|e| e.into_inner());
        if !parts.is_empty() {
            return Err(format!("{} of the file's tiles were never complete", parts.len()));
        }
        let scratch = self.scratch.path();
        self.file.end().map_err(|e| output::explain_failure(&self.target, e))?;
        // The header rewritten in place, in the room kept for it: nothing copied. Without room
        // enough, a copy with the new header (the tiles copied as compressed).
        if image_io::set_exr_header(&scratch, attributes).map_err(|e| output::explain_failure(&self.target, e))? {
            return Ok(self.scratch.into_staged(&self.target));
        }
        output::stage(&self.target, |tmp| {
            image_io::copy_exr_with_header(&scratch, tmp, attributes)
        })
    }
}

/// Writes a frame held whole (and `extra` layers made after the render: the denoised ones, in
/// `layout.plan`'s order) through a stream, a row of file tiles at a time, then stages the file
/// with `attributes` beside `target`.
pub fn write_whole(
    target: &Path,
    layout: ExrLayout,
    frame: &FrameBuffer,
    extra: &[&[Vec3]],
    attributes: &[(String, String)],
) -> Result<StagedFile, String> {
    let pixels = frame.window().pixels();
    if extra.len() != layout.plan.extra_layers() || extra.iter().any(|plane| plane.len() != pixels) {
        return Err(format!(
            "the layers made after the render do not match the frame's {}x{} pixels",
            frame.width, frame.height
        ));
    }
    let streamed = StreamedExr::open(target, layout, false)?;
    let layout = streamed.layout();
    let whole = Region {
        x0: 0,
        y0: 0,
        x1: frame.width,
        y1: frame.height,
    };
    let file_tiles = layout.file_tiles_under(whole);
    let n = layout.plan.channels.len();
    // The file's tiles filled and compressed on every core, each written as it is done.
    let next = std::sync::atomic::AtomicUsize::new(0);
    let cores = std::thread::available_parallelism().map_or(1, |c| c.get()).min(16);
    let write_tiles = || -> Result<(), String> {
        let mut values = Vec::new();
        loop {
            let k = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            let Some(&file_tile) = file_tiles.get(k) else {
                return Ok(());
            };
            values.clear();
            values.resize(file_tile.pixels() * n, 0.0);
            layout.fill_with(frame, extra, whole, file_tile, file_tile, &mut values);
            streamed.file.write_values(layout, file_tile, &values)?;
        }
    };
    let outcomes: Vec<Result<(), String>> = std::thread::scope(|scope| {
        let workers: Vec<_> = (0..cores).map(|_| scope.spawn(write_tiles)).collect();
        workers
            .into_iter()
            .map(|w| {
                w.join()
                    .unwrap_or_else(|_| Err("a thread writing the file panicked".to_string()))
            })
            .collect()
    });
    if let Some(Err(e)) = outcomes.into_iter().find(Result::is_err) {
        return Err(output::explain_failure(target, e));
    }
    streamed.finish(attributes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::components::Components;
    use crate::sys::image_io::read_image_with_header;

    /// A 37x21 region of a 50x30 image, its corner off the 16x8 tile grid, its tiles stored in
    /// reverse order: the file holds every pixel where it belongs, and the header its last
    /// attributes, whether they fit the room kept for them (the header rewritten in place) or
    /// not (the file copied under a new header).
    #[test]
    fn tiles_in_any_order_make_the_file_with_its_header_in_place_or_copied() {
        let window = PixelWindow::new(
            Region {
                x0: 5,
                y0: 3,
                x1: 42,
                y1: 24,
            },
            50,
            30,
        );
        let value = |x: u32, y: u32| Vec3::new(x as f32, y as f32, 0.25);
        let tiles = crate::tiles::tiles_in(50, 30, 16, 8, Some(window.area));
        for (room, statistics) in [(64 << 10, 2000), (0, 200_000)] {
            let dir = tempfile::tempdir().unwrap();
            let target = dir.path().join("out.exr");
            let layout = ExrLayout {
                plan: ChannelPlan::new(&[Layer::Direct], &[], false, &[]),
                window,
                tile: (16, 8),
                half_float: false,
                compression: ExrCompression::Zip,
                header_room: room,
            };
            let streamed = StreamedExr::open(&target, layout, false).unwrap();
            for tile in tiles.iter().rev() {
                let values: Vec<PixelValue> = (tile.y0..tile.y1)
                    .flat_map(|y| (tile.x0..tile.x1).map(move |x| (x, y)))
                    .map(|(x, y)| PixelValue {
                        components: Components {
                            direct: value(x, y),
                            ..Default::default()
                        },
                        ..Default::default()
                    })
                    .collect();
                streamed.store(tile, &values);
            }
            assert_eq!(
                std::fs::read_dir(dir.path()).unwrap().count(),
                0,
                "nothing named before the end"
            );
            let attributes = vec![("icrender/statistics".to_string(), "s".repeat(statistics))];
            streamed.finish(&attributes).unwrap().place().unwrap();
            let image = read_image_with_header(&target).unwrap();
            assert_eq!(
                (image.width, image.height, image.window.x, image.window.y),
                (37, 21, 5, 3)
            );
            assert_eq!(image.attribute("icrender/statistics").map(str::len), Some(statistics));
            let direct = image.channel("direct.G").unwrap();
            for (i, v) in direct.iter().enumerate() {
                let (x, y) = window.position(i);
                assert_eq!(*v, value(x, y).y, "pixel ({x}, {y}) with room {room}");
            }
            assert_eq!(image.channel("R").unwrap()[0], 5.0);
            let names: Vec<_> = std::fs::read_dir(dir.path())
                .unwrap()
                .map(|e| e.unwrap().file_name())
                .collect();
            assert_eq!(names, vec![std::ffi::OsString::from("out.exr")]);
        }
    }
}
