"""What users take away: per-pixel uncertainty maps (:mod:`.maps`), object footprints
(:mod:`.footprints`), V2X confidence fields (:mod:`.v2x`), geodetic output (:mod:`.geo`) and
multi-camera fusion (:mod:`.fusion`)."""
