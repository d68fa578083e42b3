//! Placeholder: the browser test lands here.
