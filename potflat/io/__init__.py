"""File input and output: scans, stage files, images, JSON sidecars."""
