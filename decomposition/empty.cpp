// intentionally empty until decomposition sources exist
