//! `wgcloth run --out DIR`: the frames as PNG files and one animated GIF,
//! with `--export obj` each frame's geometry as OBJ, and with `--export
//! usd` the whole run as one USD file.
//! Everything it will write is checked before the run starts, so a bad
//! directory costs no simulation and nothing is overwritten without
//! `--force`.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use image::codecs::gif::{GifEncoder, Repeat};
use image::{Delay, RgbaImage};

use glam::Vec3;

use crate::frames::obj::{obj_name, write_obj};
use crate::frames::usd::{USD_NAME, UsdRecording};
use wgcloth::error::{Error, Result};
use wgcloth::render::Frame;
use wgcloth::scene::Scene;

pub const GIF_NAME: &str = "animation.gif";

/// The PNG file of frame `k`.
pub fn frame_name(k: usize) -> String {
    format!("frame_{k:04}.png")
}

pub struct FrameWriter {
    dir: PathBuf,
    /// Created with the first drawn frame, so a run that stops before it
    /// leaves no empty animation behind.
    gif: Option<GifEncoder<BufWriter<File>>>,
    /// Display time of each GIF frame, ms (GIF counts in 10 ms).
    delay_ms: u32,
    written: usize,
    obj: bool,
    objs: usize,
    /// The run's geometry for its USD file (`--export usd`).
    usd: Option<UsdRecording>,
}

/// Which geometry files a run writes besides its frames.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Exports {
    /// A Wavefront OBJ file a frame.
    pub obj: bool,
    /// One USD file of the run.
    pub usd: bool,
}

fn image_error(path: &Path, e: image::ImageError) -> Error {
    Error::file(path, format!("cannot write: {e}"))
}

impl FrameWriter {
    /// Prepares `dir` for `frames` frames shown `delay_ms` apart (and the
    /// geometry files of `exports`): creates it if missing, and refuses a
    /// file in its place, or (without `force`) any output of ours already
    /// there.
    pub fn create(
        dir: &Path,
        frames: usize,
        (delay_ms, exports): (u32, Exports),
        force: bool,
    ) -> Result<FrameWriter> {
        if dir.exists() && !dir.is_dir() {
            return Err(Error::file(
                dir,
                "is a file, not a directory for the frames",
            ));
        }
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        let objs = (0..frames).filter(|_| exports.obj).map(obj_name);
        let usd = exports.usd.then(|| USD_NAME.to_string());
        let names = (0..frames)
            .map(frame_name)
            .chain(objs)
            .chain(usd)
            .chain([GIF_NAME.to_string()]);
        if !force && let Some(taken) = names.map(|n| dir.join(n)).find(|p| p.exists()) {
            return Err(Error::file(
                &taken,
                "already exists; pass --force to replace the frames",
            ));
        }
        Ok(FrameWriter {
            dir: dir.to_path_buf(),
            gif: None,
            delay_ms: delay_ms.next_multiple_of(10).max(20),
            written: 0,
            obj: exports.obj,
            objs: 0,
            usd: exports.usd.then(UsdRecording::default),
        })
    }

    /// The geometry of step `step`'s frame, for the exports asked for: the
    /// cloth at `x`, the body placed at the step's time.
    pub fn write_geometry(&mut self, scene: &Scene, x: &[Vec3], step: u64) -> Result<()> {
        if let Some(usd) = &mut self.usd {
            usd.push(scene, step, x);
        }
        if !self.obj {
            return Ok(());
        }
        let time = step as f32 * scene.config.solver.dt;
        write_obj(&self.dir.join(obj_name(self.objs)), scene, x, time)?;
        self.objs += 1;
        Ok(())
    }

    fn gif(&mut self) -> Result<&mut GifEncoder<BufWriter<File>>> {
        if self.gif.is_none() {
            let path = self.dir.join(GIF_NAME);
            let file = File::create(&path).map_err(|e| Error::io(&path, e))?;
            // Speed 10 of 1–30: a good palette at a tenth of the slowest's time.
            let mut gif = GifEncoder::new_with_speed(BufWriter::new(file), 10);
            gif.set_repeat(Repeat::Infinite)
                .map_err(|e| image_error(&path, e))?;
            self.gif = Some(gif);
        }
        Ok(self.gif.as_mut().expect("created above"))
    }

    /// Whether frames need their geometry (`--export`).
    pub fn wants_geometry(&self) -> bool {
        self.obj || self.usd.is_some()
    }

    pub fn write(&mut self, frame: &Frame) -> Result<()> {
        let path = self.dir.join(frame_name(self.written));
        let image = RgbaImage::from_raw(frame.width, frame.height, frame.rgba.clone())
            .ok_or_else(|| Error::file(&path, "frame size does not match its pixels"))?;
        image.save(&path).map_err(|e| image_error(&path, e))?;
        let delay = Delay::from_numer_denom_ms(self.delay_ms, 1);
        self.gif()?
            .encode_frame(image::Frame::from_parts(image, 0, 0, delay))
            .map_err(|e| image_error(&self.dir.join(GIF_NAME), e))?;
        self.written += 1;
        Ok(())
    }

    /// Frames drawn so far.
    pub fn written(&self) -> usize {
        self.written
    }

    /// What the run left: the frames drawn, the OBJ files, the GIF's path
    /// (none without a drawn frame) and the USD file's. The GIF's trailer
    /// is written as its encoder drops; the USD file is written now.
    pub fn finish(self, scene: &Scene) -> Result<Written> {
        let gif = self.gif.map(|gif| {
            drop(gif);
            self.dir.join(GIF_NAME)
        });
        let usd = match self.usd {
            Some(usd) => {
                let path = self.dir.join(USD_NAME);
                usd.write(&path, scene)?;
                Some(path)
            }
            None => None,
        };
        Ok(Written {
            dir: self.dir,
            frames: self.written,
            objs: self.objs,
            gif,
            usd,
        })
    }
}

/// What a run wrote into its frame directory.
#[derive(Clone, Debug)]
pub struct Written {
    pub dir: PathBuf,
    pub frames: usize,
    pub objs: usize,
    pub gif: Option<PathBuf>,
    pub usd: Option<PathBuf>,
}
