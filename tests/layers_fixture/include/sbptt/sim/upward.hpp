#pragma once
// A fixture for the layer check: a simulator header that includes the engine layer.
#include "sbptt/bptt/objective.hpp"
