//! Audio features and synthetic speech.
