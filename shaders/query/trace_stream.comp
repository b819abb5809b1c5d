#version 460
// Streamed renders (motu-gpu `StreamingRenderer`): the same shader with a sample's secondary
// rays traced in windows (render_pixel.glsl, MOTU_STREAMED); full builds keep the sequential
// loop, whose shape every ray of a full build pays for less.
#extension GL_GOOGLE_include_directive : require
#define MOTU_STREAMED 1
#include "query/compute.glsl"
