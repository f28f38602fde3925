//! Finding the VGG weights on this machine, or fetching them once.
