#pragma once
// A fixture for the layer check: the engine layer, included from below.
