//! Speech-like audio (syllables with pitch and formants) and the mouth track it drives.
