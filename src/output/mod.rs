//! What a render leaves behind: the multi-layer EXR (`exr`), the preview PNG through a view
//! transform (`preview`), the denoised beauty (`denoise`), and the combination of the EXRs
//! of a split render (`merge`). The film only accumulates; everything that turns it into
//! files, or reads files back into planes, is here.

pub mod denoise;
pub mod exr;
pub mod merge;
pub mod preview;
