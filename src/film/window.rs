//! A rectangle of an image's pixels: a crop window, and the EXR data window it becomes.

/// A rectangle of pixels of an image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Window {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
}

impl Window {
    /// The whole of a `width` × `height` image.
    pub fn full(width: u32, height: u32) -> Self {
        Self {
            x: 0,
            y: 0,
            width,
            height,
        }
    }

    /// Parses `X0,Y0,X1,Y1`: pixel columns X0..X1 and rows Y0..Y1 (ends excluded, origin at
    /// the top left), e.g. `0,0,320,240` for the top-left quarter of a 640x480 image.
    pub fn parse(text: &str) -> Result<Self, String> {
        let numbers: Vec<u32> = text
            .split(',')
            .map(|v| v.trim().parse::<u32>())
            .collect::<Result<_, _>>()
            .map_err(|_| format!("expected X0,Y0,X1,Y1 in pixels, got {text:?}"))?;
        match numbers[..] {
            [x0, y0, x1, y1] if x1 > x0 && y1 > y0 => Ok(Self {
                x: x0,
                y: y0,
                width: x1 - x0,
                height: y1 - y0,
            }),
            [_, _, _, _] => Err(format!(
                "the window {text:?} is empty (X1 <= X0 or Y1 <= Y0)"
            )),
            _ => Err(format!("expected X0,Y0,X1,Y1 in pixels, got {text:?}")),
        }
    }

    /// `X0,Y0,X1,Y1`, as [`Window::parse`] reads it.
    pub fn describe(&self) -> String {
        format!(
            "{},{},{},{}",
            self.x,
            self.y,
            self.x + self.width,
            self.y + self.height
        )
    }

    /// True if the window lies inside a `width` × `height` image.
    pub fn fits(&self, width: u32, height: u32) -> bool {
        self.x as u64 + self.width as u64 <= width as u64
            && self.y as u64 + self.height as u64 <= height as u64
    }

    /// This window of an image (display coordinates) in the coordinates of the image
    /// rendered with `overscan` around it.
    pub fn beyond(&self, overscan: crate::camera::Overscan) -> Self {
        Self {
            x: self.x + overscan.left,
            y: self.y + overscan.top,
            ..*self
        }
    }

    /// Number of pixels.
    pub fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// Row-major index in the window of image pixel (`x`, `y`), which must lie inside it.
    #[inline]
    pub fn index(&self, x: u32, y: u32) -> usize {
        (y - self.y) as usize * self.width as usize + (x - self.x) as usize
    }
}
