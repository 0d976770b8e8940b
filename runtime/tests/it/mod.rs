mod tracker;
