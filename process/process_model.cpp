#include "process/process_model.hpp"
