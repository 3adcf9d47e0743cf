"""Hardware bridge core (issue 9): ADS symbol map, link, safety logic and the test peer."""
