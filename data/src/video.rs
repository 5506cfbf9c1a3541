//! Rollout videos: RGB frames encoded as H.264 (OpenH264, built from its bundled source by the
//! `openh264` crate) in an mp4 container (the `mp4` crate), 20 fps by default — what browsers,
//! `ffprobe` and LeRobot's video readers open. Written to a temporary file beside the target and
//! renamed when finished, so a reader never sees half a video.
//!
//! ```no_run
//! let mut v = data::video::VideoWriter::create("ep.mp4", 64, 32, 20)?;
//! v.push(&vec![0u8; 64 * 32 * 3])?;
//! v.finish()?;
//! # Ok::<(), data::DataError>(())
//! ```

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use openh264::encoder::{Encoder, EncoderConfig};
use openh264::formats::{RgbSliceU8, YUVBuffer};

use crate::error::{DataError, Result};

/// Height of the caption band under a rollout frame (two lines of 8×8 glyphs).
pub const CAPTION_HEIGHT: usize = 24;

/// What a rollout frame's caption says.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Caption {
    /// Control step of the observation.
    pub step: usize,
    /// The task's step budget.
    pub budget: usize,
    /// Subgoals satisfied, goal length, over-repeated (None: no task goal).
    pub progress: Option<(usize, usize, bool)>,
    /// The pending subgoal's text (None once the goal is complete).
    pub pending: Option<String>,
}

/// One rollout frame `[S + 24, 2·S, 3]`: agentview | eye-in-hand (`[S, S, 3]` each) side by side,
/// and under them the step of the budget, the subgoals satisfied and the pending subgoal (what
/// `eval --video` and `sim generate --video` write). None when the images are not `[S, S, 3]`.
pub fn frame(
    agentview: &[u8],
    eye_in_hand: &[u8],
    s: usize,
    caption: &Caption,
) -> Option<(Vec<u8>, usize, usize)> {
    if s == 0 || agentview.len() != s * s * 3 || eye_in_hand.len() != s * s * 3 {
        return None;
    }
    let (w, h) = (2 * s, s + CAPTION_HEIGHT);
    let mut img = image::RgbImage::new(w as u32, h as u32);
    for y in 0..s {
        for x in 0..s {
            let i = (y * s + x) * 3;
            let (a, e) = (&agentview[i..i + 3], &eye_in_hand[i..i + 3]);
            img.put_pixel(x as u32, y as u32, image::Rgb([a[0], a[1], a[2]]));
            img.put_pixel((s + x) as u32, y as u32, image::Rgb([e[0], e[1], e[2]]));
        }
    }
    let line1 = match caption.progress {
        Some((done, len, failed)) => format!(
            "step {}/{}  {done}/{len} done{}",
            caption.step,
            caption.budget,
            if failed { "  OVER-REPEATED" } else { "" }
        ),
        None => format!("step {}/{}", caption.step, caption.budget),
    };
    let line2 = match &caption.pending {
        Some(p) => format!("next: {p}"),
        None => "goal complete".to_string(),
    };
    for (row, text) in [(s + 3, line1), (s + 14, line2)] {
        let fit = crate::draw::fitting(&text, w as u32 - 4, 8).to_string();
        crate::draw::text(&mut img, 2, row as i64, &fit, [235, 235, 235], 8);
    }
    Some((img.into_raw(), w, h))
}

/// Encoder settings of a [`VideoWriter`] beyond size and rate.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct VideoOptions {
    /// A key frame every this many frames (0: the encoder decides; readers that seek, as
    /// LeRobot's do, decode from the key frame before the frame asked for).
    pub keyframe_every: u32,
    /// Never drop a frame (every pushed frame becomes one sample, so frame k is at time k / fps):
    /// buffer-based rate control without frame skipping, where the default quality mode may skip
    /// frames to hold its bit rate.
    pub every_frame: bool,
}

/// Media time units per second of the video track.
const TIMESCALE: u32 = 10_000;

/// An mp4 being written, frame by frame.
pub struct VideoWriter {
    path: PathBuf,
    tmp: Option<tempfile::NamedTempFile>,
    encoder: Encoder,
    mp4: Option<mp4::Mp4Writer<BufWriter<File>>>,
    width: usize,
    height: usize,
    frame_ticks: u32,
    frames: u64,
    /// Bytes of encoded samples so far.
    bytes: u64,
    /// Encoded frames waiting for the first SPS/PPS (the track's configuration).
    pending: Vec<(Vec<u8>, bool)>,
}

fn video_err(path: &Path, m: impl std::fmt::Display) -> DataError {
    DataError::Invalid {
        path: path.to_path_buf(),
        msg: format!("video: {m}"),
    }
}

/// NAL unit type of a NAL (start code stripped).
fn nal_type(nal: &[u8]) -> u8 {
    nal.first().map_or(0, |b| b & 0x1f)
}

/// A NAL without its Annex-B start code.
fn strip_start_code(nal: &[u8]) -> &[u8] {
    if nal.starts_with(&[0, 0, 0, 1]) {
        &nal[4..]
    } else if nal.starts_with(&[0, 0, 1]) {
        &nal[3..]
    } else {
        nal
    }
}

impl VideoWriter {
    /// Starts `path` for `width × height` frames (both even, ≥ 16) at `fps` frames per second.
    pub fn create(path: impl AsRef<Path>, width: usize, height: usize, fps: u32) -> Result<Self> {
        Self::create_with(path, width, height, fps, VideoOptions::default())
    }

    /// [`VideoWriter::create`] with encoder settings.
    pub fn create_with(
        path: impl AsRef<Path>,
        width: usize,
        height: usize,
        fps: u32,
        opts: VideoOptions,
    ) -> Result<Self> {
        let path = path.as_ref().to_path_buf();
        if width < 16 || height < 16 || width % 2 == 1 || height % 2 == 1 || fps == 0 {
            return Err(video_err(
                &path,
                format!("{width}×{height} at {fps} fps: sides must be even and at least 16"),
            ));
        }
        let dir = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        std::fs::create_dir_all(dir).map_err(|e| DataError::io(dir, e))?;
        let tmp = tempfile::Builder::new()
            .prefix(".video-")
            .suffix(".mp4.tmp")
            .tempfile_in(dir)
            .map_err(|e| DataError::io(dir, e))?;
        let mut config = EncoderConfig::new()
            .max_frame_rate(openh264::encoder::FrameRate::from_hz(fps as f32))
            .num_threads(1);
        if opts.keyframe_every > 0 {
            config = config.intra_frame_period(
                openh264::encoder::IntraFramePeriod::from_num_frames(opts.keyframe_every),
            );
        }
        if opts.every_frame {
            config = config
                .skip_frames(false)
                .rate_control_mode(openh264::encoder::RateControlMode::Bufferbased);
        }
        let encoder = Encoder::with_api_config(openh264::OpenH264API::from_source(), config)
            .map_err(|e| video_err(&path, e))?;
        Ok(VideoWriter {
            path,
            tmp: Some(tmp),
            encoder,
            mp4: None,
            width,
            height,
            frame_ticks: TIMESCALE / fps,
            frames: 0,
            bytes: 0,
            pending: Vec::new(),
        })
    }

    /// Appends one RGB frame `[height, width, 3]`.
    pub fn push(&mut self, rgb: &[u8]) -> Result<()> {
        if rgb.len() != self.width * self.height * 3 {
            return Err(video_err(
                &self.path,
                format!(
                    "a frame of {} bytes, expected {}×{}×3",
                    rgb.len(),
                    self.height,
                    self.width
                ),
            ));
        }
        let yuv = YUVBuffer::from_rgb_source(RgbSliceU8::new(rgb, (self.width, self.height)));
        let stream = self
            .encoder
            .encode(&yuv)
            .map_err(|e| video_err(&self.path, e))?;
        let (mut sps, mut pps) = (None, None);
        let mut sample = Vec::new();
        let mut sync = false;
        for l in 0..stream.num_layers() {
            let layer = stream.layer(l).expect("layer within count");
            for n in 0..layer.nal_count() {
                let nal = strip_start_code(layer.nal_unit(n).expect("nal within count"));
                match nal_type(nal) {
                    7 => sps = Some(nal.to_vec()),
                    8 => pps = Some(nal.to_vec()),
                    t => {
                        sync |= t == 5;
                        sample.extend_from_slice(&(nal.len() as u32).to_be_bytes());
                        sample.extend_from_slice(nal);
                    }
                }
            }
        }
        if self.mp4.is_none()
            && let (Some(sps), Some(pps)) = (sps, pps)
        {
            self.start_track(sps, pps)?;
        }
        self.pending.push((sample, sync));
        if self.mp4.is_some() {
            for (bytes, sync) in std::mem::take(&mut self.pending) {
                self.write_sample(bytes, sync)?;
            }
        }
        Ok(())
    }

    /// Makes the next pushed frame a key frame (an IDR picture), e.g. where an episode starts.
    pub fn force_keyframe(&mut self) {
        self.encoder.force_intra_frame();
    }

    fn start_track(&mut self, sps: Vec<u8>, pps: Vec<u8>) -> Result<()> {
        let tmp = self.tmp.as_ref().expect("open until finished");
        let file = tmp.reopen().map_err(|e| DataError::io(tmp.path(), e))?;
        let brands = ["isom", "iso2", "avc1", "mp41"];
        let config = mp4::Mp4Config {
            major_brand: "isom".parse().expect("four letters"),
            minor_version: 512,
            compatible_brands: brands
                .iter()
                .map(|b| b.parse().expect("four letters"))
                .collect(),
            timescale: 1000,
        };
        let mut w = mp4::Mp4Writer::write_start(BufWriter::new(file), &config)
            .map_err(|e| video_err(&self.path, e))?;
        w.add_track(&mp4::TrackConfig {
            track_type: mp4::TrackType::Video,
            timescale: TIMESCALE,
            language: "und".into(),
            media_conf: mp4::MediaConfig::AvcConfig(mp4::AvcConfig {
                width: self.width as u16,
                height: self.height as u16,
                seq_param_set: sps,
                pic_param_set: pps,
            }),
        })
        .map_err(|e| video_err(&self.path, e))?;
        self.mp4 = Some(w);
        Ok(())
    }

    fn write_sample(&mut self, bytes: Vec<u8>, sync: bool) -> Result<()> {
        let sample_len = bytes.len() as u64;
        let sample = mp4::Mp4Sample {
            start_time: self.frames * self.frame_ticks as u64,
            duration: self.frame_ticks,
            rendering_offset: 0,
            is_sync: sync,
            bytes: bytes.into(),
        };
        self.mp4
            .as_mut()
            .expect("track started")
            .write_sample(1, &sample)
            .map_err(|e| video_err(&self.path, e))?;
        self.frames += 1;
        self.bytes += sample_len;
        Ok(())
    }

    /// Frames written so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// Bytes of encoded video written so far (the file is this plus its headers and index).
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// Finishes the file (moov box) and moves it to its path; the number of frames.
    pub fn finish(mut self) -> Result<u64> {
        let Some(mut w) = self.mp4.take() else {
            return Err(video_err(&self.path, "no frame was encoded"));
        };
        if !self.pending.is_empty() {
            return Err(video_err(
                &self.path,
                "frames without a stream configuration",
            ));
        }
        w.write_end().map_err(|e| video_err(&self.path, e))?;
        let mut out = w.into_writer();
        std::io::Write::flush(&mut out).map_err(|e| DataError::io(&self.path, e))?;
        let file = out
            .into_inner()
            .map_err(|e| DataError::io(&self.path, e.into_error()))?;
        // Readable by a web server like any other output (temporary files start private).
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            file.set_permissions(std::fs::Permissions::from_mode(0o644))
                .map_err(|e| DataError::io(&self.path, e))?;
        }
        file.sync_all().map_err(|e| DataError::io(&self.path, e))?;
        let tmp = self.tmp.take().expect("open until finished");
        tmp.persist(&self.path)
            .map_err(|e| DataError::io(&self.path, e.error))?;
        Ok(self.frames)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame with a moving bright square on a gradient.
    fn pattern(w: usize, h: usize, t: usize) -> Vec<u8> {
        let mut v = vec![0u8; w * h * 3];
        for y in 0..h {
            for x in 0..w {
                let i = (y * w + x) * 3;
                v[i] = (x * 255 / w) as u8;
                v[i + 1] = (y * 255 / h) as u8;
                let inside = (x + w - t % w) % w < 8 && (4..12).contains(&y);
                v[i + 2] = if inside { 255 } else { 40 };
            }
        }
        v
    }

    #[test]
    fn an_mp4_with_one_h264_track_and_every_frame() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sub/ep.mp4");
        let (w, h) = (48, 32);
        let mut v = VideoWriter::create(&path, w, h, 20).unwrap();
        for t in 0..30 {
            v.push(&pattern(w, h, t)).unwrap();
        }
        assert!(!path.exists(), "nothing at the path until finished");
        assert_eq!(v.finish().unwrap(), 30);
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(&bytes[4..8], b"ftyp");
        let size = bytes.len() as u64;
        let mut r = mp4::Mp4Reader::read_header(std::io::Cursor::new(bytes), size).unwrap();
        let track = r.tracks().get(&1).expect("track 1");
        assert_eq!(track.media_type().unwrap(), mp4::MediaType::H264);
        assert_eq!((track.width(), track.height()), (w as u16, h as u16));
        assert_eq!(r.sample_count(1).unwrap(), 30);
        assert_eq!(track.duration().as_millis(), 1500);
        let first = r.read_sample(1, 1).unwrap().unwrap();
        assert!(first.is_sync, "the first frame is a key frame");
        // AVCC: length-prefixed NAL units filling the sample exactly.
        let b = &first.bytes[..];
        let mut i = 0;
        while i < b.len() {
            let n = u32::from_be_bytes(b[i..i + 4].try_into().unwrap()) as usize;
            i += 4 + n;
        }
        assert_eq!(i, b.len());
        // No temporary file is left beside it.
        let names: Vec<_> = std::fs::read_dir(path.parent().unwrap())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("ep.mp4")]);
    }

    #[test]
    fn frames_put_the_cameras_side_by_side_over_the_caption() {
        let s = 16;
        let a = vec![200u8; s * s * 3];
        let e = vec![10u8; s * s * 3];
        let caption = Caption {
            step: 3,
            budget: 200,
            progress: Some((1, 3, false)),
            pending: Some("bowl 1 on plate 1".into()),
        };
        let (rgb, w, h) = frame(&a, &e, s, &caption).unwrap();
        assert_eq!((w, h), (32, 40));
        assert_eq!(rgb[..3], [200, 200, 200], "agentview on the left");
        assert_eq!(
            rgb[(5 * w + 20) * 3..][..3],
            [10, 10, 10],
            "eye-in-hand on the right"
        );
        let band = &rgb[s * w * 3..];
        assert!(band.contains(&235), "caption text drawn");
        assert!(frame(&a, &e[1..], s, &caption).is_none());
    }

    #[test]
    fn bad_sizes_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let e = VideoWriter::create(dir.path().join("a.mp4"), 33, 32, 20)
            .err()
            .unwrap();
        assert!(e.to_string().contains("sides must be even"), "{e}");
        let mut v = VideoWriter::create(dir.path().join("b.mp4"), 32, 32, 20).unwrap();
        let e = v.push(&[0; 10]).unwrap_err();
        assert!(
            e.to_string()
                .contains("a frame of 10 bytes, expected 32×32×3"),
            "{e}"
        );
        let e = v.finish().unwrap_err();
        assert!(e.to_string().contains("no frame was encoded"), "{e}");
        assert!(
            std::fs::read_dir(dir.path()).unwrap().next().is_none(),
            "nothing left"
        );
    }
}
