//! `wgcloth run --out DIR`: the frames as PNG files and one animated GIF,
//! and with `--export obj` each frame's geometry as OBJ.
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
    /// Created with the first drawn frame, so a run that draws none (no
    /// adapter) leaves no empty animation behind.
    gif: Option<GifEncoder<BufWriter<File>>>,
    /// Display time of each GIF frame, ms (GIF counts in 10 ms).
    delay_ms: u32,
    written: usize,
    obj: bool,
    objs: usize,
}

fn image_error(path: &Path, e: image::ImageError) -> Error {
    Error::file(path, format!("cannot write: {e}"))
}

impl FrameWriter {
    /// Prepares `dir` for `frames` frames shown `delay_ms` apart (with an
    /// OBJ file each if `obj`): creates it if missing, and refuses a file
    /// in its place, or (without `force`) any output of ours already there.
    pub fn create(
        dir: &Path,
        frames: usize,
        (delay_ms, obj): (u32, bool),
        force: bool,
    ) -> Result<FrameWriter> {
        if dir.exists() && !dir.is_dir() {
            return Err(Error::file(
                dir,
                "is a file, not a directory for the frames",
            ));
        }
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        let objs = (0..frames).filter(|_| obj).map(obj_name);
        let names = (0..frames)
            .map(frame_name)
            .chain(objs)
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
            obj,
            objs: 0,
        })
    }

    /// The next frame's geometry, when OBJ export is on: cloth at `x`, the
    /// body placed at `time`.
    pub fn write_obj(&mut self, scene: &Scene, x: &[Vec3], time: f32) -> Result<()> {
        if !self.obj {
            return Ok(());
        }
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

    pub fn wants_obj(&self) -> bool {
        self.obj
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

    /// What the run left: the frames drawn, the OBJ files, and the GIF's
    /// path (none without a drawn frame). The GIF's trailer is written as
    /// its encoder drops.
    pub fn finish(self) -> Written {
        let gif = self.gif.map(|gif| {
            drop(gif);
            self.dir.join(GIF_NAME)
        });
        Written {
            dir: self.dir,
            frames: self.written,
            objs: self.objs,
            gif,
        }
    }
}

/// What a run wrote into its frame directory.
#[derive(Clone, Debug)]
pub struct Written {
    pub dir: PathBuf,
    pub frames: usize,
    pub objs: usize,
    pub gif: Option<PathBuf>,
}
